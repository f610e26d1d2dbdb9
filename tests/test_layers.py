"""Dependencies point one way: core <- actors, chaos <- supervisor <- tools (DESIGN.md, issue 32).

Every import in the package counts, lazy ones inside functions included: a lazy upward import is
still a dependency, it only fails later. Edges that exist today and are being removed are listed
in KNOWN_UPWARD with the module that holds them; the test fails on any edge not listed there, and
on a listed edge that is gone (so the list only shrinks and never hides a fixed one).
"""
from __future__ import annotations

import ast
from pathlib import Path
import pytest

pytestmark = pytest.mark.unit

ROOT = Path(__file__).resolve().parents[1]
# Folder on disk -> package it imports as (pyproject's package-dir).
FOLDERS = {"emos": "emos", "actors": "emos.actors", "supervisor": "emos.supervisor", "chaos": "emos.chaos"}

# Tiers, lowest first. A module may import its own tier's package and anything lower; actors and
# chaos are siblings and import neither each other nor anything above. The tools tier (the CLI,
# benchmarks, the BARN harness, the chaos drivers) will get its own package (issue 32); until then
# its modules sit in the tiers below and appear in KNOWN_UPWARD.
TIER = {"emos": 0, "emos.actors": 1, "emos.chaos": 1, "emos.supervisor": 2}

# The one sanctioned upward call: the Launcher facade starts the supervisor when bringup runs.
ALLOWED = {("emos.launcher", "emos.supervisor"),
           # `python -m emos` is the CLI's entry point: run, never imported by anything.
           ("emos.__main__", "emos.supervisor")}

# Upward edges found when this check was written, by importing module -> imported package.
KNOWN_UPWARD: set[tuple[str, str]] = {
    # Benchmarks and the BARN harness drive whole systems: they belong in the tools tier.
    ("emos.actors.agents.bench_system", "emos.supervisor"),
    ("emos.actors.nav.bench_navloop", "emos.supervisor"),
    ("emos.actors.sim.barn", "emos.supervisor"),
    ("emos.actors.sim.barn.process", "emos.supervisor"),
    ("emos.actors.sim.barn.report", "emos.supervisor"),
    ("emos.actors.sim.barn.report_plot", "emos.supervisor"),
    ("emos.actors.sim.bench_component", "emos.supervisor"),
    ("emos.actors.ui.bench", "emos.supervisor"),
    # A chaos scenario starting the model server: a chaos driver, so a tool.
    ("emos.chaos.recipes.model_drop", "emos.actors"),
    # The Launcher imports the UI and the Foxglove view: they should register themselves.
    ("emos.launcher", "emos.actors"),
    # Status over Zenoh uses the supervisor's process helpers.
    ("emos.transport.zenoh_status", "emos.supervisor"),
}


def _package_of(module: str) -> str:
    for pkg in sorted(TIER, key=len, reverse=True):
        if module == pkg or module.startswith(pkg + "."):
            return pkg
    return ""


def _module_name(path: Path) -> str:
    rel = path.relative_to(ROOT)
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


def upward_edges() -> set[tuple[str, str]]:
    edges = set()
    for folder in FOLDERS:
        for path in sorted((ROOT / folder).rglob("*.py")):
            module = _module_name(path)
            own = _package_of(module)
            for target in _imports(path, module):
                other = _package_of(target)
                if not other or other == own or (module, other) in ALLOWED:
                    continue
                if TIER[other] >= TIER[own]:
                    edges.add((module, other))
    return edges


def test_no_module_imports_a_tier_above_its_own():
    edges = upward_edges()
    new = sorted(edges - KNOWN_UPWARD)
    gone = sorted(KNOWN_UPWARD - edges)
    assert not new, "upward imports (module -> package of a higher or sibling tier):\n  " + "\n  ".join(f"{m} -> {p}" for m, p in new)
    assert not gone, "these known upward imports are gone: remove them from KNOWN_UPWARD:\n  " + "\n  ".join(f"{m} -> {p}" for m, p in gone)


def test_the_check_sees_lazy_and_relative_imports(tmp_path):
    source = "def f():\n    from emos.supervisor.spawn import die_with\n\nfrom ..ui import launch\nimport emos.chaos.nemesis\n"
    path = tmp_path / "x.py"
    path.write_text(source)
    found = _imports(path, "emos.actors.sim.x")
    assert "emos.supervisor.spawn" in found and "emos.actors.ui" in found and "emos.chaos.nemesis" in found
