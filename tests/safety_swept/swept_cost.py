"""Cost per command of the swept-footprint check: the version at git HEAD (``old``) and the
working tree's (``new``) interleaved in one run, on ``emos bench nav``'s commands (bench_swept's
scan and commands), thread CPU time per call; per command class too, and the decisions of both
compared (they must be the same).

``python3 -m tests.safety_swept.swept_cost [--rounds 5] [--commands 500] [--ref REV]``
(not a test: a measurement; the load is printed beside the numbers)."""
from __future__ import annotations

import argparse
import importlib.util
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]


def load_ref(rev: str):
    """The check module as it was at ``rev``, imported under its own name beside the current one."""
    src = subprocess.run(["git", "show", f"{rev}:actors/nav/safety/swept.py"], cwd=ROOT, check=True,
                         capture_output=True, text=True).stdout
    with tempfile.NamedTemporaryFile("w", suffix=".py", delete=False) as f:
        f.write(src)
    try:
        name = "emos.actors.nav.safety._swept_ref"
        spec = importlib.util.spec_from_file_location(name, f.name)
        mod = importlib.util.module_from_spec(spec)
        mod.__package__ = "emos.actors.nav.safety"
        sys.modules[name] = mod
        spec.loader.exec_module(mod)
    finally:
        os.unlink(f.name)
    return mod


def setup(commands: int):
    """bench_swept's robot, scan and commands (tools/bench/nav.py), the same seed."""
    from emos.actors.sim.robots import PRESETS
    from emos.tools.barn.harness import nav_robot
    from emos.tools.bench.nav import _circle_scan

    rng = np.random.default_rng(38)
    robot = nav_robot(PRESETS["jackal-barn"])
    xy = rng.uniform(-3.0, 3.0, (60, 2))
    xy = xy[np.hypot(xy[:, 0], xy[:, 1]) > robot.radius + 0.2]
    points = _circle_scan(np.zeros(3), [(float(x), float(y), 0.075) for x, y in xy]).points()
    cmds = np.c_[rng.uniform(-0.5, 2.0, commands), np.zeros(commands), rng.uniform(-3.0, 3.0, commands)]
    prevs = np.clip(cmds + np.c_[rng.normal(0, 0.2, commands), np.zeros(commands), rng.normal(0, 0.3, commands)], -3, 3)
    return robot, points, cmds, prevs


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--commands", type=int, default=500)
    ap.add_argument("--ref", default="HEAD")
    ap.add_argument("--classes", action="store_true", help="p50/p99 per command class and decision")
    ap.add_argument("--history", action="store_true",
                    help="pass a history of sent commands as the DriveManager does (the last 0.3 s at 20 Hz, near the previous command)")
    args = ap.parse_args()
    from emos.actors.nav.safety import swept as new_mod

    old_mod = load_ref(args.ref)
    robot, points, cmds, prevs = setup(args.commands)
    old, new = old_mod.SweptFootprint(robot), new_mod.SweptFootprint(robot)
    po, pn = old.prepare(points), new.prepare(points)
    load0 = os.getloadavg()
    t = {"old": np.zeros((args.rounds, len(cmds))), "new": np.zeros((args.rounds, len(cmds)))}
    rng = np.random.default_rng(7)
    times = -0.05 * np.arange(6)[::-1]  # sent 0.25 s ago .. now, 20 Hz
    histories = [(times, prev + rng.normal(0.0, 0.1, (6, 3)) * [1.0, 0.0, 1.0]) if args.history else None for prev in prevs]
    differ = []
    for r in range(args.rounds):
        for i, (cmd, prev) in enumerate(zip(cmds, prevs)):
            order = (("old", old, po), ("new", new, pn)) if (i + r) % 2 else (("new", new, pn), ("old", old, po))
            res = {}
            for name, check, prepared in order:
                c0 = time.thread_time()
                res[name] = check.check(cmd, prev, prepared, lead=0.02, history=histories[i])
                t[name][r, i] = time.thread_time() - c0
            a, b = res["old"], res["new"]
            if r == 0 and (a.scale != b.scale or a.blocked != b.blocked or abs(a.clearance - b.clearance) > 1e-9
                           and not (np.isinf(a.clearance) and np.isinf(b.clearance))):
                differ.append((i, a, b))
    load1 = os.getloadavg()
    print(f"load before {load0[0]:.2f} after {load1[0]:.2f} (1-min); {len(points)} points, {len(cmds)} commands x {args.rounds}"
          + ("; with a history of sent commands" if args.history else ""))
    print(f"decisions differ: {len(differ)}" + (f", first {differ[:3]}" if differ else ""))
    for name in ("old", "new"):
        ms = 1e3 * t[name]
        best = ms.min(axis=0)
        print(f"{name}: all calls p50 {np.percentile(ms, 50):.3f} p99 {np.percentile(ms, 99):.3f} max {ms.max():.3f} ms; "
              f"best-of-{args.rounds} per command p50 {np.percentile(best, 50):.3f} p99 {np.percentile(best, 99):.3f} ms")
    decisions = [old.check(c, p, po, lead=0.02, history=h) for c, p, h in zip(cmds, prevs, histories)]
    slow = np.array([d.scale < 1.0 for d in decisions])
    o, n = 1e3 * t["old"].min(axis=0), 1e3 * t["new"].min(axis=0)
    print(f"commands slowed or stopped ({slow.sum()}): best-of-{args.rounds} mean old {o[slow].mean():.3f} new {n[slow].mean():.3f} ms "
          f"(new/old {n[slow].mean() / o[slow].mean():.2f}); the rest: old {o[~slow].mean():.3f} new {n[~slow].mean():.3f} ms")
    if args.classes:
        cls = np.array([("rev" if c[0] < -0.05 else "rot" if abs(c[0]) < 0.3 else "slow" if c[0] < 1.0 else "fast")
                        + "/" + ("free" if d.scale == 1.0 and np.isinf(d.clearance) else "clear" if d.scale == 1.0
                                 else "blocked" if d.blocked else "stop" if d.scale == 0.0 else "slowed")
                        for c, d in zip(cmds, decisions)])
        for k in sorted(set(cls)):
            sel = cls == k
            o, n = 1e3 * t["old"][:, sel], 1e3 * t["new"][:, sel]
            print(f"  {k:<14} n={sel.sum():>3}  old p50 {np.percentile(o, 50):.3f} p99 {np.percentile(o, 99):.3f}   "
                  f"new p50 {np.percentile(n, 50):.3f} p99 {np.percentile(n, 99):.3f}")
    return 0 if not differ else 1


if __name__ == "__main__":
    raise SystemExit(main())
