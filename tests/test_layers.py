"""Dependencies point one way: core <- actors <- supervisor <- tools, chaos (DESIGN.md, issue 32).

Every import in the package counts, lazy ones inside functions included: a lazy upward import is
still a dependency, it only fails later. KNOWN_UPWARD lists edges waiting to be removed, with
the module that holds them (empty now: every edge found in issue 32 is gone); the test fails on
any edge not listed there, and on a listed edge that is gone (so the list only shrinks and never
hides a fixed one).
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

pytestmark = pytest.mark.unit

ROOT = Path(__file__).resolve().parents[1]
# Folder on disk -> package it imports as (pyproject's package-dir).
FOLDERS = {"emos": "emos", "actors": "emos.actors", "supervisor": "emos.supervisor", "chaos": "emos.chaos",
           "tools": "emos.tools"}

# Tiers, lowest first. A module may import its own tier and anything lower, never a tier above.
# The tools tier sits above the product: the CLI, every benchmark and the BARN harness
# (emos.tools), and chaos, whose nemeses and scenarios drive whole systems as a test harness does;
# so the CLI may run chaos scenarios and chaos may start the product's components.
TOOLS = 3
TIER = {"emos": 0, "emos.actors": 1, "emos.supervisor": 2, "emos.tools": TOOLS, "emos.chaos": TOOLS}

# The one sanctioned upward call: the Launcher facade starts the supervisor when bringup runs.
ALLOWED = {("emos.launcher", "emos.supervisor"),
           # `python -m emos` is the CLI's entry point: run, never imported by anything.
           ("emos.__main__", "emos.tools")}

# Upward edges waiting to be removed, by importing module -> imported package. Issue 32 removed
# the eleven found when this check was written (benchmarks, the BARN harness and the CLI moved to
# emos.tools; the Launcher finds the UI and the Foxglove view through entry points; the Zenoh
# status reads process helpers from emos.core). Keep it empty: fix a new edge, do not list it.
KNOWN_UPWARD: set[tuple[str, str]] = set()


def _package_of(module: str) -> str:
    for pkg in sorted(TIER, key=len, reverse=True):
        if module == pkg or module.startswith(pkg + "."):
            return pkg
    return ""


def _module_name(path: Path, root: Path = ROOT) -> str:
    rel = path.relative_to(root)
    parts = list(rel.with_suffix("").parts)
    parts[0] = FOLDERS[parts[0]]
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _imports(path: Path, module: str) -> set[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    is_package = path.name == "__init__.py"
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = module.split(".")
                base = base[: len(base) - node.level + (1 if is_package else 0)]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            found.add(target)
            # `from emos import actors` imports a subpackage by name.
            found.update(f"{target}.{alias.name}" for alias in node.names)
    return {name for name in found if name == "emos" or name.startswith("emos.")}


def upward_edges(root: Path = ROOT) -> set[tuple[str, str]]:
    edges = set()
    for folder in FOLDERS:
        for path in sorted((root / folder).rglob("*.py")):
            module = _module_name(path, root)
            own = _package_of(module)
            for target in _imports(path, module):
                other = _package_of(target)
                if not other or other == own or (module, other) in ALLOWED:
                    continue
                if TIER[other] > TIER[own]:
                    edges.add((module, other))
    return edges


def test_no_module_imports_a_tier_above_its_own():
    edges = upward_edges()
    new = sorted(edges - KNOWN_UPWARD)
    gone = sorted(KNOWN_UPWARD - edges)
    assert not new, "upward imports (module -> package of a higher tier):\n  " + "\n  ".join(f"{m} -> {p}" for m, p in new)
    assert not gone, "these known upward imports are gone: remove them from KNOWN_UPWARD:\n  " + "\n  ".join(f"{m} -> {p}" for m, p in gone)


def test_the_check_sees_lazy_and_relative_imports(tmp_path):
    source = "def f():\n    from emos.supervisor.spawn import die_with\n\nfrom ..ui import launch\nimport emos.chaos.nemesis\n"
    path = tmp_path / "x.py"
    path.write_text(source)
    found = _imports(path, "emos.actors.sim.x")
    assert "emos.supervisor.spawn" in found and "emos.actors.ui" in found and "emos.chaos.nemesis" in found


def test_an_upward_import_in_any_tier_fails_the_check(tmp_path):
    """The same walk over a small tree: each kind of upward edge is reported, downward ones are not."""
    files = {
        "emos/core/x.py": "def f():\n    from emos.actors.ui import frontend\n",          # core -> actors, lazily
        "actors/sim/y.py": "import emos.tools.barn\n",                                      # actors -> tools
        "supervisor/z.py": "from emos.chaos import nemesis\n",                              # supervisor -> chaos (tools tier)
        "chaos/w.py": "from emos.actors.agents import LLM\nfrom emos.tools.cli import main\n",  # down, and within the tier
        "tools/bench/v.py": "from emos.supervisor.system import System\n",                  # down
    }
    for name, source in files.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(source)
    assert upward_edges(tmp_path) == {("emos.core.x", "emos.actors"), ("emos.actors.sim.y", "emos.tools"),
                                      ("emos.supervisor.z", "emos.chaos")}
