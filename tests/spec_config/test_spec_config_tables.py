"""Every config field the spec documents exists on our class, with the documented default.

The fields are read from the spec's own text (``tests/spec_data/``, verbatim slices of
``emos-docs.md``), not copied by eye:

* ``{list-table}`` tables whose header has a Name and a Default column (the navigation
  algorithms' parameter tables), mapped to a class through the ``##`` heading they sit under;
* Markdown pipe tables with a Parameter/Name and a Default column (the events reference);
* field lists written ``**`name`** *(type, default=value)*`` under a sentence naming the config
  class (the motion-testing page);
* "inherits all parameters from X": the names (and, except where listed below, the defaults) of
  X's table must exist on the inheriting class too;
* the OMPL planners' "Planner Default Parameters" lists: every parameter the spec lists for a
  planner we offer must be settable through ``OMPLConfig.planner_params`` (its default is OMPL's
  own, since we pass on only what the user sets);
* a few defaults the spec states in a sentence, each found by a pattern in the page's text.

A new table under a heading this file does not map is a failure, so a spec update cannot be
skipped silently.
"""
from __future__ import annotations

import ast
import importlib
import inspect
import math
import re
from enum import Enum
from pathlib import Path
from typing import Any

import attrs
import numpy as np
import pytest

pytestmark = pytest.mark.unit

SPEC = Path(__file__).resolve().parent.parent / "spec_data"
PAGES = sorted(p.relative_to(SPEC).as_posix() for p in SPEC.rglob("*.md") if p.name != "README.md")

# Our class for each class name the spec uses (the spec's import line -> ours).
CLASSES = {
    "DWAConfig": "emos.actors.nav.controllers:DWAConfig",
    "PurePursuitConfig": "emos.actors.nav.controllers:PurePursuitConfig",
    "StanleyConfig": "emos.actors.nav.controllers:StanleyConfig",
    "DVZConfig": "emos.actors.nav.controllers:DVZConfig",
    "VisionRGBFollowerConfig": "emos.actors.nav.controllers:VisionRGBFollowerConfig",
    "VisionRGBDFollowerConfig": "emos.actors.nav.controllers:VisionRGBDFollowerConfig",
    "TrajectoryCostsWeights": "emos.actors.nav.costs:TrajectoryCostsWeights",
    "MotionServerConfig": "emos.actors.nav.components:MotionServerConfig",
    "Event": "emos:Event",
    "VLMConfig": "emos.actors.agents:VLMConfig",
    "MapLayer": "emos.actors.agents:MapLayer",
    "RoboBrain2": "emos.actors.agents:RoboBrain2",
}

# The class a parameter table documents, by the ``##`` heading it sits under (the headings name
# the algorithm, and the page's examples name the config class).
SECTION_CLASS = {
    "Dynamic Window Approach (DWA)": "DWAConfig",
    "Pure Pursuit": "PurePursuitConfig",
    "Stanley Steering": "StanleyConfig",
    "Deformable Virtual Zone (DVZ)": "DVZConfig",
    "Vision Follower (RGB)": "VisionRGBFollowerConfig",
    "Vision Follower (RGB-D)": "VisionRGBDFollowerConfig",
    "Trajectory Cost Evaluation": "TrajectoryCostsWeights",
    "Event Configuration Reference": "Event",
}

# Defaults stated in a sentence: (page, pattern whose group 1 is the default, class, field).
PROSE_DEFAULTS = [
    ("recipes/foundation/conversational-agent.md", r"`break_character` in the config \(Default: '([^']*)'\)",
     "VLMConfig", "break_character"),
    ("recipes/foundation/semantic-map.md", r"_temporal_change_ parameter.*?By default this option is set to \*\*(\w+)\*\*",
     "MapLayer", "temporal_change"),
    ("intelligence/models.md", r"RoboBrain 2\.0.*?Checkpoint defaults to `\"([^\"]+)\"`", "RoboBrain2", "checkpoint"),
]

# The justified exceptions: (class, field) -> why our default differs from the spec's.
# Only inherited defaults are excepted; every field a table lists for a class is checked.
EXCEPTIONS = {
    ("VisionRGBDFollowerConfig", "control_horizon"):
        "inherited from DWA, where it is seconds (0.2); the vision followers count it in control steps "
        "(the vision-tracking page: 'control_horizon equal to three future control time steps'), default 2 steps",
}

# Planner parameters the spec lists for a planner we offer that cannot be set through the
# installed ompl binding (registry.PlannerSpec.unsupported says so in its error message).
PLANNER_EXCEPTIONS = {
    ("BFMT", "balanced"): "the ompl 2.x binding exposes no setter for it",
    ("BFMT", "optimality"): "the ompl 2.x binding exposes no setter for it",
}


# --------------------------------------------------------------------------- reading the spec
@attrs.define
class Table:
    page: str
    section: str  # the ``##`` heading above the table
    anchor_heading: str  # the nearest heading of any level above it
    rows: list[dict[str, str]]
    intro: str  # the text between the nearest heading and the table


def _page(name: str) -> str:
    return (SPEC / name).read_text(encoding="utf-8")


def _clean(cell: str) -> str:
    return cell.strip().replace("**", "").strip().strip("`").strip()


def _headings(lines: list[str]) -> list[tuple[int, int, str]]:
    """(line index, level, title) of the ``##``..``######`` headings. Level 1 is left out: the
    flattened spec's code blocks lost their indentation, so a ``# comment`` line looks like one."""
    out = []
    for i, line in enumerate(lines):
        m = re.match(r"^(#{2,6}) (.+)$", line)
        if m and not line.startswith("## File:"):
            out.append((i, len(m.group(1)), m.group(2).strip()))
    return out


def _context(headings: list[tuple[int, int, str]], at: int, lines: list[str]) -> tuple[str, str, str]:
    section = nearest = ""
    nearest_at = 0
    for i, level, title in headings:
        if i > at:
            break
        if level == 2:
            section = title
        nearest, nearest_at = title, i
    return section, nearest, "\n".join(lines[nearest_at + 1:at])


def list_tables(page: str) -> list[Table]:
    """The ``{list-table}`` tables of a page (rows ``* - a`` then ``- b``, indented or not)."""
    lines = _page(page).split("\n")
    heads = _headings(lines)
    tables, i = [], 0
    while i < len(lines):
        if lines[i].strip() != "```{list-table}":
            i += 1
            continue
        start, header_rows, rows = i, 0, []
        i += 1
        while i < len(lines) and lines[i].strip() != "```":
            line = lines[i].strip()
            if line.startswith(":header-rows:"):
                header_rows = int(line.split(":")[2])
            elif line.startswith("* - "):
                rows.append([line[4:]])
            elif line.startswith("- ") and rows:
                rows[-1].append(line[2:])
            elif line and rows and not line.startswith(":"):
                rows[-1][-1] += " " + line  # a cell continued on the next line
            i += 1
        if header_rows == 1 and rows:
            header = [_clean(c).lower() for c in rows[0]]
            section, nearest, intro = _context(heads, start, lines)
            tables.append(Table(page, section, nearest, [dict(zip(header, (_clean(c) for c in r))) for r in rows[1:]], intro))
        i += 1
    return tables


def pipe_tables(page: str) -> list[Table]:
    lines = _page(page).split("\n")
    heads = _headings(lines)
    tables, i = [], 0
    while i < len(lines):
        if not (lines[i].startswith("|") and i + 1 < len(lines) and re.match(r"^\|[\s:|-]+\|$", lines[i + 1].strip())):
            i += 1
            continue
        start = i
        header = [_clean(c).lower() for c in lines[i].strip().strip("|").split("|")]
        i += 2
        rows = []
        while i < len(lines) and lines[i].startswith("|"):
            rows.append(dict(zip(header, (_clean(c) for c in lines[i].strip().strip("|").split("|")))))
            i += 1
        section, nearest, intro = _context(heads, start, lines)
        tables.append(Table(page, section, nearest, rows, intro))
    return tables


def _is_field_table(table: Table) -> bool:
    keys = set(table.rows[0]) if table.rows else set()
    return "default" in keys and bool(keys & {"name", "parameter", "field"})


def _name(row: dict[str, str]) -> str:
    return row.get("name") or row.get("parameter") or row["field"]


def field_tables() -> list[tuple[Table, str]]:
    """(table, class name) of every table of config fields in the copied pages."""
    found = []
    for page in PAGES:
        for table in list_tables(page) + pipe_tables(page):
            if _is_field_table(table):
                found.append((table, SECTION_CLASS.get(table.section, "")))
    return found


_BULLET = re.compile(r"\*\*`(\w+)`\*\*\s*\*\(([^,)]+)(?:,\s*default=([^)]*))?\)\*")


def field_lists() -> list[tuple[str, str, list[tuple[str, str, str | None]]]]:
    """(page, class, [(field, type, default or None)]) of the ``**`name`** *(type, default=x)*`` lists;
    the class is the one named in backticks on the line that introduces the list."""
    out = []
    for page in PAGES:
        lines = _page(page).split("\n")
        i = 0
        while i < len(lines):
            if not _BULLET.search(lines[i]):
                i += 1
                continue
            intro = next((lines[j] for j in range(i - 1, -1, -1) if lines[j].strip()), "")
            owner = re.findall(r"`(\w+)`", intro)
            items = []
            while i < len(lines) and (m := _BULLET.search(lines[i])):
                items.append((m.group(1), m.group(2).strip(), m.group(3)))
                i += 1
            out.append((page, owner[-1] if owner else "", items))
    return out


def planner_parameters() -> dict[str, list[str]]:
    """Planner -> parameter names, from the "Planner Default Parameters" lists."""
    lines = _page("advanced/algorithms.md").split("\n")
    start = lines.index("### Planner Default Parameters")
    planners: dict[str, list[str]] = {}
    current = None
    for line in lines[start + 1:]:
        if line.startswith("#### "):
            current = line[5:].strip()
            planners[current] = []
        elif line.startswith("#") or line.startswith("```"):
            break
        elif current and (m := re.match(r"^\s*- (\w+): ", line)):
            planners[current].append(m.group(1))
    return planners


# --------------------------------------------------------------------------- values
@attrs.define(frozen=True)
class Ref:
    """"see [defaults](#anchor)": the default instance of the class documented under that heading."""

    anchor: str


_SAFE_NAMES = {"np.pi": math.pi, "math.pi": math.pi, "pi": math.pi}


def _arith(text: str) -> float:
    """``np.pi / 16`` and the like: numbers, pi and + - * / only."""
    def ev(node: ast.AST) -> float:
        if isinstance(node, ast.Expression):
            return ev(node.body)
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) and not isinstance(node.value, bool):
            return node.value
        if isinstance(node, (ast.Name, ast.Attribute)) and ast.unparse(node) in _SAFE_NAMES:
            return _SAFE_NAMES[ast.unparse(node)]
        if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
            return -ev(node.operand)
        if isinstance(node, ast.BinOp) and isinstance(node.op, (ast.Add, ast.Sub, ast.Mult, ast.Div)):
            a, b = ev(node.left), ev(node.right)
            return {ast.Add: a + b, ast.Sub: a - b, ast.Mult: a * b, ast.Div: a / b if b else math.nan}[type(node.op)]
        raise ValueError(f"not a spec default this test can read: {text!r}")
    return ev(ast.parse(text, mode="eval"))


def spec_value(text: str) -> Any:
    """The spec's default cell as a Python value: None, bool, number, string, tuple, or Ref."""
    text = text.strip().strip("`").strip()
    if (m := re.search(r"\]\(#([\w-]+)\)", text)) and text.lower().startswith("see"):
        return Ref(m.group(1))
    if text in ("None", "True", "False"):
        return {"None": None, "True": True, "False": False}[text]
    try:
        value = ast.literal_eval(text)
    except (ValueError, SyntaxError):
        return _arith(text)
    return tuple(value) if isinstance(value, list) else value


def our_class(name: str) -> type:
    module, _, attr = CLASSES[name].partition(":")
    return getattr(importlib.import_module(module), attr)


_MISSING = object()


def our_default(cls: type, name: str) -> Any:
    """The default of ``name`` on ``cls`` (an attrs class, or a plain class's __init__ keyword);
    ``_MISSING`` if there is no such field."""
    if attrs.has(cls):
        fields = attrs.fields_dict(cls)
        if name not in fields:
            return _MISSING
        try:
            return getattr(cls(), name)  # defaults as the class builds them (factories, converters)
        except TypeError:  # a class with required fields: its declared default
            default = fields[name].default
            return default.factory() if isinstance(default, attrs.Factory) else default
    parameter = inspect.signature(cls).parameters.get(name)
    if parameter is None:
        return _MISSING
    return None if parameter.default is inspect.Parameter.empty else parameter.default


def _numeric(value: Any) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))


def same(spec: Any, ours: Any, spec_type: str = "") -> bool:
    """The spec's default and ours agree: numbers to 1e-9, sequences element-wise, enums by value,
    and an ``int``/``bool`` in the spec's type column must be one here too."""
    if isinstance(ours, Enum):
        ours = ours.value
    if spec is None or isinstance(spec, bool):
        return ours is spec or (isinstance(ours, np.bool_) and bool(ours) is spec)
    if _numeric(spec):
        if not _numeric(ours) or not math.isclose(float(spec), float(ours), rel_tol=1e-9, abs_tol=1e-12):
            return False
        return not (spec_type.strip("`") == "int" and not float(ours).is_integer())
    if isinstance(spec, tuple):
        arr = np.asarray(ours, dtype=np.float64).ravel() if ours is not None else None
        return arr is not None and arr.shape == (len(spec),) and np.allclose(arr, np.asarray(spec, dtype=np.float64))
    return spec == ours


def _anchor(title: str) -> str:
    return re.sub(r"[^\w\s-]", "", title.lower()).strip().replace(" ", "-")


def _expected(value: Any, tables: list[tuple[Table, str]]) -> Any:
    if isinstance(value, Ref):
        owners = [cls for t, cls in tables if _anchor(t.anchor_heading) == value.anchor]
        assert owners, f"the spec refers to #{value.anchor}, which heads no table of fields here"
        return our_class(owners[0])()
    return value


# --------------------------------------------------------------------------- the checks
def _check_rows(cls_name: str, rows: list[tuple[str, str, Any]], tables: list[tuple[Table, str]],
                inherited: bool = False) -> list[str]:
    cls = our_class(cls_name)
    problems = []
    for name, spec_type, default in rows:
        ours = our_default(cls, name)
        if ours is _MISSING:
            problems.append(f"{cls_name}.{name}: missing (the spec documents it, default {default!r})")
            continue
        if inherited and (cls_name, name) in EXCEPTIONS:
            continue
        if default is _MISSING:  # the spec gives no default: existence is all it documents
            continue
        want = _expected(spec_value(default), tables)
        if not same(want, ours, spec_type):
            problems.append(f"{cls_name}.{name}: default {ours!r}, the spec says {default} ({spec_type or 'no type'})")
    return problems


def test_the_copied_spec_pages_are_there_and_hold_the_tables():
    assert PAGES, f"no spec pages under {SPEC}"
    tables = field_tables()
    # The navigation algorithms (7) and the events reference (1) at the time of copying: fewer
    # means the parser broke, not that the spec lost tables.
    assert len(tables) >= 8, [(t.page, t.section) for t, _ in tables]
    assert all(len(t.rows) >= 3 for t, _ in tables)


def test_every_table_of_config_fields_is_mapped_to_a_class():
    unmapped = [(t.page, t.section) for t, cls in field_tables() if not cls]
    assert not unmapped, f"tables of config fields under headings SECTION_CLASS does not map: {unmapped}"


@pytest.mark.parametrize("cls_name", sorted(set(SECTION_CLASS.values())))
def test_table_fields_exist_with_the_documented_defaults(cls_name):
    tables = field_tables()
    mine = [t for t, cls in tables if cls == cls_name]
    assert mine, f"no table of {cls_name}'s fields found in the spec pages"
    problems = []
    for table in mine:
        rows = [(_name(r), r.get("type", ""), r["default"]) for r in table.rows]
        problems += _check_rows(cls_name, rows, tables)
        # "inherits all parameters from DWA": the parent's table applies here too
        for acronym in re.findall(r"inherits all parameters from (\w+)", table.intro):
            parents = [t for t, _ in tables if f"({acronym})" in t.section]
            assert parents, f"{cls_name}: the spec says it inherits from {acronym}, whose table was not found"
            own = {name for name, _, _ in rows}
            inherited = [(_name(r), r.get("type", ""), r["default"]) for r in parents[0].rows if _name(r) not in own]
            problems += _check_rows(cls_name, inherited, tables, inherited=True)
    assert not problems, "\n".join(problems)


def test_field_lists_exist_with_the_documented_defaults():
    lists = field_lists()
    assert [cls for _, cls, _ in lists] == ["MotionServerConfig"], lists  # the lists at the time of copying
    problems = []
    for page, cls_name, items in lists:
        assert cls_name in CLASSES, f"{page}: a field list of {cls_name!r}, which CLASSES does not map"
        problems += _check_rows(cls_name, [(n, t, d if d is not None else _MISSING) for n, t, d in items], field_tables())
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("page, pattern, cls_name, field", PROSE_DEFAULTS, ids=[f"{c}.{f}" for _, _, c, f in PROSE_DEFAULTS])
def test_defaults_stated_in_the_text(page, pattern, cls_name, field):
    m = re.search(pattern, _page(page), flags=re.S)
    assert m, f"{page}: the sentence stating {cls_name}.{field}'s default is gone ({pattern!r})"
    text = m.group(1)
    want = spec_value(text) if text in ("True", "False", "None") else text
    ours = our_default(our_class(cls_name), field)
    assert ours is not _MISSING, f"{cls_name}.{field}: missing"
    assert same(want, ours), f"{cls_name}.{field}: default {ours!r}, the spec says {text!r}"


def test_every_planner_parameter_the_spec_lists_can_be_set():
    pytest.importorskip("ompl")
    from emos.actors.nav.planning.registry import PlannerNotAvailableError, available_planners, planner_spec

    listed = planner_parameters()
    assert len(listed) >= 29, sorted(listed)  # the spec's 29 planners
    offered = set(available_planners())
    problems, unavailable = [], []
    for planner, params in listed.items():
        if planner not in offered:
            # Not in the installed ompl binding: resolving it must say so (tests/nav covers the message).
            with pytest.raises(PlannerNotAvailableError):
                planner_spec(planner)
            unavailable.append(planner)
            continue
        spec = planner_spec(planner)
        for name in params:
            if name in spec.params:
                continue
            if (planner, name) in PLANNER_EXCEPTIONS:
                assert name in spec.unsupported, f"{planner}.{name}: excepted here, but the registry does not say it is unsupported"
                continue
            problems.append(f"{planner}: the spec lists parameter {name!r}, planner_params cannot set it")
    assert not problems, "\n".join(problems)
    assert offered, "no spec planner is available in the installed ompl binding"


@pytest.mark.parametrize("key", sorted(EXCEPTIONS), ids=[".".join(k) for k in sorted(EXCEPTIONS)])
def test_each_exception_is_still_needed(key):
    """An exception whose default now matches (or whose field is gone) must be removed from the list."""
    cls_name, name = key
    tables = field_tables()
    parent_rows = [r for t, _ in tables for r in t.rows if _name(r) == name and t.section != next(
        s for s, c in SECTION_CLASS.items() if c == cls_name)]
    assert parent_rows, f"{cls_name}.{name}: no inherited spec row to except"
    ours = our_default(our_class(cls_name), name)
    assert ours is not _MISSING
    assert not same(_expected(spec_value(parent_rows[0]["default"]), tables), ours, parent_rows[0].get("type", "")), \
        f"{cls_name}.{name} now has the spec's default: remove it from EXCEPTIONS"
