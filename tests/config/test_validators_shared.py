"""Field validators have one home, ``emos.config.validators`` (issue 32, "one concept, one home").

Three parts: the shared validators' contract (what they accept, the exception type, a message
that names ``Class.field``, what was expected and the value); configs that used local copies
accept and refuse the same values through the shared ones; and a source scan that fails on a new
local copy of a generic check (``_positive``, ``_nonneg``, ``_positive_int``, ...).
"""
from __future__ import annotations

import ast
import math
import re
from pathlib import Path

import attrs
import pytest

from emos.config import validators as V

pytestmark = pytest.mark.unit

ROOT = Path(__file__).resolve().parents[2]


@attrs.define
class Sample:
    length: float = attrs.field(default=1.0, validator=V.finite_positive)
    margin: float = attrs.field(default=0.0, validator=V.finite_non_negative)
    count: int = attrs.field(default=2, validator=V.int_at_least(2))
    timeout: float | None = attrs.field(default=None, validator=V.positive_or_none)
    name: str = attrs.field(default="a", validator=V.non_empty_str)
    port: int = attrs.field(default=80, validator=V.number(ge=1, le=65535, integer=True, what="a TCP port"))
    ratio: float = attrs.field(default=0.5, validator=V.number(ge=0, lt=1, finite=True))
    inner: Path = attrs.field(factory=Path, validator=V.instance_of(Path))
    _hidden: int = attrs.field(default=1, validator=V.int_at_least(1))


@pytest.mark.parametrize("field, good", [
    ("length", [1e-9, 3, 2.5]), ("margin", [0, 0.0, 7]), ("count", [2, 10**6]), ("timeout", [None, 0.1, 5]),
    ("name", ["x", " y "]), ("port", [1, 65535]), ("ratio", [0, 0.999]), ("inner", [Path("/tmp")]),
])
def test_shared_validators_accept(field, good):
    for value in good:
        Sample(**{field: value})


@pytest.mark.parametrize("field, bad, error, message", [
    ("length", 0, ValueError, "Sample.length must be a finite number > 0, got 0"),
    ("length", math.inf, ValueError, "Sample.length must be a finite number > 0, got inf"),
    ("length", math.nan, ValueError, "got nan"),
    ("length", True, ValueError, "got True"),  # a bool is not a number here
    ("length", "1", ValueError, "got '1'"),
    ("margin", -1e-9, ValueError, "Sample.margin must be a finite number >= 0"),
    ("count", 1, ValueError, "Sample.count must be an integer >= 2, got 1"),
    ("count", 2.0, ValueError, "must be an integer >= 2, got 2.0"),
    ("timeout", 0, ValueError, "Sample.timeout must be a number > 0 or None, got 0"),
    ("timeout", math.nan, ValueError, "got nan"),
    ("name", "  ", ValueError, "Sample.name must be a non-empty string, got '  '"),
    ("name", None, ValueError, "got None"),
    ("port", 0, ValueError, "Sample.port must be a TCP port in [1, 65535], got 0"),
    ("ratio", 1, ValueError, "Sample.ratio must be a finite number in [0, 1), got 1"),
    ("inner", "/tmp", TypeError, "Sample.inner must be a Path, got str '/tmp'"),
    ("hidden", 0, ValueError, "Sample.hidden must be an integer >= 1, got 0"),  # the init name, not _hidden
])
def test_shared_validators_refuse_with_a_message_naming_the_field(field, bad, error, message):
    with pytest.raises(error) as info:
        Sample(**{field: bad})
    assert message in str(info.value)


def test_existing_validators_keep_their_contract():
    @attrs.define
    class Old:
        rate: float = attrs.field(default=1.0, validator=V.in_range(0.5, 2.0))
        mode: str = attrs.field(default="a", validator=V.in_(["a", "b"]))
        stop: float = attrs.field(default=1.0, validator=V.positive)

    with pytest.raises(TypeError, match=r"Old\.rate expects a number in \[0.5, 2.0\], got 'x'"):
        Old(rate="x")
    with pytest.raises(ValueError, match=r"Old\.rate must be in \[0.5, 2.0\], got 3"):
        Old(rate=3)
    with pytest.raises(ValueError, match=r"Old\.mode must be one of \['a', 'b'\], got 'c'"):
        Old(mode="c")
    with pytest.raises(ValueError, match=r"Old\.stop must be a positive number, got 0"):
        Old(stop=0)
    Old(stop=math.inf)  # positive alone never asked for finite
    # Only in_range and in_ describe a form (UI): the new ones leave forms as they were.
    assert V.in_range(0, 1).emos_range == (0, 1) and V.in_([1]).emos_choices == [1]
    assert not hasattr(V.finite_positive, "emos_range") and not hasattr(V.int_at_least(1), "emos_range")


def _refuses(build, error, message):
    with pytest.raises(error) as info:
        build()
    assert message in str(info.value), str(info.value)


def test_configs_that_had_local_copies_accept_and_refuse_as_before():
    from emos.actors.agents.db.spec import ChromaDB
    from emos.actors.agents.models.vision import VisionModel
    from emos.actors.nav.components.base import NavComponentConfig
    from emos.actors.nav.controllers.arcs import ArcConfig
    from emos.actors.nav.planning.config import OMPLConfig
    from emos.actors.nav.robot import LinearCtrlLimits, RobotFrames
    from emos.actors.sim.clock import SimClock

    ArcConfig(margin=0, reverse_speed=0)
    _refuses(lambda: ArcConfig(horizon=0), ValueError, "ArcConfig.horizon must be a finite number > 0, got 0")
    _refuses(lambda: ArcConfig(step=math.inf), ValueError, "ArcConfig.step must be a finite number > 0")
    _refuses(lambda: ArcConfig(speeds=1), ValueError, "ArcConfig.speeds must be an integer >= 2, got 1")
    SimClock(dt=1e-4)
    _refuses(lambda: SimClock(dt=0), ValueError, "SimClock.dt must be a positive number, got 0.0")
    LinearCtrlLimits(max_vel=0, max_acc=1, max_decel=2)  # a disabled axis
    _refuses(lambda: LinearCtrlLimits(max_vel=1, max_acc=0, max_decel=1), ValueError,
             "LinearCtrlLimits.max_acc must be a finite acceleration > 0, got 0.0")
    _refuses(lambda: LinearCtrlLimits(max_vel=math.inf, max_acc=1, max_decel=1), ValueError, "finite speed >= 0")
    _refuses(lambda: RobotFrames(odom=" "), ValueError, "RobotFrames.odom must be a non-empty string")
    _refuses(lambda: NavComponentConfig(robot=3), TypeError, "NavComponentConfig.robot must be a RobotConfig, got int 3")
    _refuses(lambda: ChromaDB(port=0), ValueError, "ChromaDB.port must be a TCP port in [1, 65535], got 0")
    _refuses(lambda: ChromaDB(port=True), ValueError, "ChromaDB.port must be a TCP port")
    _refuses(lambda: ChromaDB(request_timeout=0), ValueError, "ChromaDB.request_timeout must be a number of seconds > 0")
    _refuses(lambda: OMPLConfig(occupied_threshold=101), ValueError,
             "OMPLConfig.occupied_threshold must be an integer in [0, 100], got 101")
    _refuses(lambda: VisionModel(name="x", num_trackers=0), ValueError, "VisionModel.num_trackers must be an integer >= 1")
    # Single-field checks that were hand-written in __attrs_post_init__.
    from emos.actors.nav.controllers.response import ResponseConfig
    from emos.actors.sim.sensors.camera import CameraConfig
    from emos.actors.sim.sensors.lidar import LidarConfig

    ResponseConfig(forgetting=1.0)
    _refuses(lambda: ResponseConfig(forgetting=1.01), ValueError, "ResponseConfig.forgetting must be a number in (0, 1], got 1.01")
    LidarConfig(fov_deg=360, beams=2)
    _refuses(lambda: LidarConfig(fov_deg=361), ValueError, "LidarConfig.fov_deg must be a number in (0, 360], got 361.0")
    _refuses(lambda: LidarConfig(beams=1), ValueError, "LidarConfig.beams must be an integer >= 2, got 1")
    _refuses(lambda: LidarConfig(rate_hz=math.nan), ValueError, "LidarConfig.rate_hz must be a finite number > 0, got nan")
    _refuses(lambda: CameraConfig(vfov_deg=179), ValueError, "CameraConfig.vfov_deg must be a number in [1, 179), got 179.0")


# Generic checks that belong in emos.config.validators, by the names their local copies had.
GENERIC = re.compile(r"^_(positive|pos|nonneg|non_negative|positive_int|pos_int|non_empty|finite_pos\w*|positive_finite"
                     r"|int_at_least|unit_interval|optional_number|instance|instance_of|finite_number|count|cap)$")
FOLDERS = ("emos", "actors", "supervisor", "chaos")
# Not field validators (plain helpers with other signatures), and files other work owns.
SKIP = {"actors/agents/clients/base.py"}


def _attrs_validator_args(fn: ast.FunctionDef) -> bool:
    names = [a.arg for a in fn.args.args]
    return len(names) == 3 or any(isinstance(n, ast.FunctionDef) and len(n.args.args) == 3 for n in ast.walk(fn) if n is not fn)


def test_no_local_copies_of_generic_validators():
    found = []
    for folder in FOLDERS:
        for path in sorted((ROOT / folder).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            if rel in SKIP or "/bench" in rel or "/barn/" in rel:
                continue
            tree = ast.parse(path.read_text(), filename=rel)
            for node in tree.body:
                if isinstance(node, ast.FunctionDef) and GENERIC.match(node.name) and _attrs_validator_args(node):
                    found.append(f"{rel}:{node.lineno} {node.name}")
    assert not found, f"use emos.config.validators instead of local copies: {found}"
