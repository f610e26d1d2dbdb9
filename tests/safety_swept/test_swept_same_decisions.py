"""The swept-footprint check, made cheaper, decides as before: the answers (scale, blocked,
clearance) of the check as it was at e9ef098 (before its per-call overhead was cut), recorded
over generated scans and commands, are the answers of the check today.

The recorded file holds the inputs too (rounded, so that they are exact in JSON), so the cases
do not depend on a random generator's stream. To record it again from a version of the check
(only when its decisions are meant to change, with the reason in the commit):
``python3 -m tests.safety_swept.test_swept_same_decisions --record``.
"""
from __future__ import annotations

import json
import math
import os
import sys
from pathlib import Path

import numpy as np
import pytest

from emos.actors.nav.robot import AngularCtrlLimits, LinearCtrlLimits, RobotConfig
from emos.actors.nav.safety import swept as swept_module
from emos.actors.nav.safety.swept import SweptConfig, SweptFootprint
from tests.c_build import can_build_c_extensions

pytestmark = pytest.mark.unit

DATA = Path(__file__).parent / "data" / "swept_decisions.json"


def _robots() -> dict[str, RobotConfig]:
    """The realistic Jackal box (tools/barn/harness.py nav_robot's limits) and a round robot
    (the check's bounding-circle branch)."""
    box = RobotConfig(model_type="DIFFERENTIAL_DRIVE", geometry_type="BOX", geometry_params=np.array([0.458, 0.4156, 0.282]),
                      ctrl_vx_limits=LinearCtrlLimits(max_vel=2.0, max_acc=20.0, max_decel=20.0),
                      ctrl_omega_limits=AngularCtrlLimits(max_vel=4.0, max_acc=25.0, max_decel=25.0))
    round_ = RobotConfig(model_type="DIFFERENTIAL_DRIVE", geometry_type="CYLINDER", geometry_params=np.array([0.25, 0.3]),
                         ctrl_vx_limits=LinearCtrlLimits(max_vel=1.0, max_acc=3.0, max_decel=5.0),
                         ctrl_omega_limits=AngularCtrlLimits(max_vel=2.0, max_acc=6.0, max_decel=8.0))
    return {"box": box, "round": round_}


def _configs() -> dict[str, SweptConfig]:
    return {"default": SweptConfig(), "hysteresis": SweptConfig(hysteresis=0.015, latency=0.05, max_gains=8)}


def generate(seed: int = 2211) -> dict:
    """Scans of BARN-like posts (some near the robot, as when it squeezes through a gap) and,
    per scan, commands over the speed range with previous commands near them, leads, and
    for some a history of sent commands."""
    rng = np.random.default_rng(seed)
    scans = []
    for i in range(8):
        posts = rng.uniform(-2.5, 2.5, (45 + 5 * i, 2))
        posts = posts[np.hypot(posts[:, 0], posts[:, 1]) > 0.33 + 0.02 * (i % 3)]
        angles = np.linspace(0.0, 2.0 * math.pi, 8, endpoint=False)
        ring = np.concatenate([p + 0.075 * np.c_[np.cos(angles), np.sin(angles)] for p in posts])
        scans.append(np.round(ring, 3).tolist())
    cases = []
    for n in range(360):
        cmd = [rng.uniform(-0.5, 2.0), 0.0, rng.uniform(-3.0, 3.0)]
        if n % 9 == 0:
            cmd = [0.0, 0.0, rng.uniform(-3.0, 3.0)]  # pure rotations
        prev = [float(np.clip(c + rng.normal(0.0, 0.3), -3.0, 3.0)) if j != 1 else 0.0 for j, c in enumerate(cmd)]
        case = {"robot": "box" if n % 5 else "round", "config": "hysteresis" if n % 7 == 3 else "default",
                "scan": n % len(scans), "command": np.round(cmd, 4).tolist(), "previous": np.round(prev, 4).tolist(),
                "lead": round(float(rng.uniform(0.0, 0.1)), 4)}
        if n % 4 == 1:
            times = np.round(np.sort(rng.uniform(-0.3, 0.0, 4)), 4)
            sent = np.round(np.c_[rng.uniform(-0.5, 2.0, 4), np.zeros(4), rng.uniform(-3.0, 3.0, 4)], 4)
            case["history"] = [times.tolist(), sent.tolist()]
        cases.append(case)
    return {"scans": scans, "cases": cases}


def decide(data: dict, native: bool | None = None) -> list[list]:
    """The check's answer per case: [scale, blocked, clearance] (clearance as a string: inf).
    ``native``: SweptFootprint's (the C inner loop or not; None: as installed)."""
    robots, configs = _robots(), _configs()
    checks = {(r, c): SweptFootprint(robots[r], configs[c], native=native) for r in robots for c in configs}
    prepared = {}
    out = []
    for case in data["cases"]:
        key = (case["robot"], case["config"])
        check = checks[key]
        if (key, case["scan"]) not in prepared:
            prepared[key, case["scan"]] = check.prepare(np.array(data["scans"][case["scan"]]))
        history = None
        if "history" in case:
            history = (np.array(case["history"][0]), np.array(case["history"][1]))
        result = check.check(np.array(case["command"]), np.array(case["previous"]), prepared[key, case["scan"]],
                             lead=case["lead"], history=history)
        out.append([result.scale, result.blocked, repr(float(result.clearance))])
    return out


NATIVE = [False, pytest.param(True, marks=pytest.mark.skipif(
    swept_module.NATIVE is None, reason="the C inner loop is not built (no compiler at install, or EMOS_SWEPT=python)"))]


@pytest.mark.parametrize("native", NATIVE, ids=["numpy", "c"])
def test_the_check_decides_as_the_recorded_version_did(native):
    recorded = json.loads(DATA.read_text())
    now = decide(recorded, native)
    expected = recorded["decisions"]
    assert len(now) == len(expected) == len(recorded["cases"])
    differ = [(i, e, n) for i, (e, n) in enumerate(zip(expected, now)) if e[:2] != n[:2]]
    assert not differ, f"{len(differ)} of {len(now)} decisions changed, first: {differ[:3]}"
    # The clearance reported with each answer: the same to rounding (the order of a few
    # floating-point operations may differ; the decisions above are exact).
    for i, (e, n) in enumerate(zip(expected, now)):
        assert float(n[2]) == pytest.approx(float(e[2]), abs=1e-9), (i, e, n)


def test_the_c_inner_loop_is_built_wherever_a_compiler_is():
    """Else the check would silently run at numpy's cost (p99 about 1 ms against 0.4)."""
    if not can_build_c_extensions() or os.environ.get("EMOS_SWEPT", "").lower() == "python":
        pytest.skip("no C compiler or Python headers here, or the C inner loop turned off")
    assert swept_module.NATIVE is not None, ("emos.actors.nav.safety._cswept is missing: run `pip install -e .` "
                                             "again and read the compiler's output")
    assert SweptFootprint(_robots()["box"])._native is swept_module.NATIVE


def test_the_recorded_set_exercises_every_answer():
    """Not a vacuous comparison: the set holds commands let through, slowed, stopped and blocked."""
    decisions = json.loads(DATA.read_text())["decisions"]
    scales = {d[0] for d in decisions}
    assert 1.0 in scales and 0.0 in scales and scales - {0.0, 1.0}
    assert any(d[1] for d in decisions) and any(d[0] == 0.0 and not d[1] for d in decisions)


if __name__ == "__main__":
    if "--record" not in sys.argv:
        raise SystemExit("usage: python3 -m tests.safety_swept.test_swept_same_decisions --record")
    data = generate()
    data["decisions"] = decide(data)
    DATA.parent.mkdir(exist_ok=True)
    DATA.write_text(json.dumps(data, separators=(",", ":")) + "\n")
    print(f"recorded {len(data['decisions'])} decisions into {DATA}")
