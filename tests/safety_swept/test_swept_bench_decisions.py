"""The swept-footprint check decides on ``emos bench nav``'s 500 commands (bench_swept: the
realistic Jackal among BARN-like posts) as the recorded version did: the commands whose cost the
benchmark reports (the slow ones are the stopped and slowed ones, 53% of them) keep their
answers when the check is made cheaper.

The recorded file holds the inputs (the scan's points and the commands, rounded so that they
are exact in JSON) and the answers of the check as it was at 336c990 (before the cost of its
slow path was cut for issue 38). To record it again (only when the decisions are meant to change,
with the reason in the commit): ``python3 -m tests.safety_swept.test_swept_bench_decisions --record``.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from emos.actors.nav.safety.swept import SweptFootprint

pytestmark = pytest.mark.unit

DATA = Path(__file__).parent / "data" / "swept_bench_decisions.json"
LEAD = 0.02  # s: bench_swept's lead


def _robot():
    from emos.actors.sim.robots import PRESETS
    from emos.tools.barn.harness import nav_robot

    return nav_robot(PRESETS["jackal-barn"])


def generate() -> dict:
    """bench_swept's scan and commands (tools/bench/nav.py, the same seed), rounded."""
    from emos.tools.bench.nav import _circle_scan

    rng = np.random.default_rng(38)
    robot = _robot()
    commands = 500
    xy = rng.uniform(-3.0, 3.0, (60, 2))
    xy = xy[np.hypot(xy[:, 0], xy[:, 1]) > robot.radius + 0.2]
    points = _circle_scan(np.zeros(3), [(float(x), float(y), 0.075) for x, y in xy]).points()
    cmds = np.c_[rng.uniform(-0.5, 2.0, commands), np.zeros(commands), rng.uniform(-3.0, 3.0, commands)]
    prevs = np.clip(cmds + np.c_[rng.normal(0, 0.2, commands), np.zeros(commands), rng.normal(0, 0.3, commands)], -3, 3)
    return {"points": np.round(points, 5).tolist(), "commands": np.round(cmds, 5).tolist(),
            "previous": np.round(prevs, 5).tolist()}


def decide(data: dict) -> list[list]:
    """[scale, blocked, clearance] per command (clearance as a string: inf)."""
    check = SweptFootprint(_robot())
    prepared = check.prepare(np.array(data["points"]))
    out = []
    for cmd, prev in zip(data["commands"], data["previous"]):
        result = check.check(np.array(cmd), np.array(prev), prepared, lead=LEAD)
        out.append([result.scale, result.blocked, repr(float(result.clearance))])
    return out


def test_the_benchmark_commands_are_decided_as_recorded():
    recorded = json.loads(DATA.read_text())
    now, expected = decide(recorded), recorded["decisions"]
    assert len(now) == len(expected) == len(recorded["commands"]) == 500
    differ = [(i, e, n) for i, (e, n) in enumerate(zip(expected, now)) if e[:2] != n[:2]]
    assert not differ, f"{len(differ)} of {len(now)} decisions changed, first: {differ[:3]}"
    for i, (e, n) in enumerate(zip(expected, now)):
        assert float(n[2]) == pytest.approx(float(e[2]), abs=1e-9), (i, e, n)
    # Not vacuous: the set holds commands let through, slowed, stopped and blocked.
    scales = {d[0] for d in expected}
    assert 1.0 in scales and 0.0 in scales and scales - {0.0, 1.0} and any(d[1] for d in expected)


if __name__ == "__main__":
    if "--record" not in sys.argv:
        raise SystemExit("usage: python3 -m tests.safety_swept.test_swept_bench_decisions --record")
    data = generate()
    data["decisions"] = decide(data)
    DATA.write_text(json.dumps(data, separators=(",", ":")) + "\n")
    print(f"recorded {len(data['decisions'])} decisions into {DATA}")
