#!/usr/bin/env python3
"""Where does the BARN stack's localization drift? Record one process-mode trial, replay it offline.

``record`` runs one trial through the component processes (as ``emos bench barn`` does) and
keeps what the LocalMapper was given (every scan, the wheel + IMU odometry), what it believed
(its localized pose) and the truth, in one ``.npz`` file. ``replay`` feeds the recorded scans
and odometry through a ``MemoryMapper`` configured as the stack's and prints, every few
seconds, how far its pose is from the truth, next to the odometry's own error. A replay of the
shipped mapper reproduces the recorded belief (world 51 of the moving-obstacle set, seed
3638140114: 0.43 m recorded, 0.43 m replayed), so a change to the matcher can be tried on the
real trial in a minute instead of a run of trials.

    python scripts/barn_pose_replay.py record --dynabarn --world 51 --seed 3638140114 -o t51.npz
    python scripts/barn_pose_replay.py replay t51.npz
"""
from __future__ import annotations

import argparse
import bisect
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np


def record(args: argparse.Namespace) -> int:
    from emos import msgs as M
    from emos.tools.barn.harness import BarnRules
    from emos.tools.barn.process import run_episode_process
    from emos.tools.barn.stack import GROUND_TRUTH_TOPIC, LOCALIZED_POSE_TOPIC, StackOptions
    from emos.transport.pubsub import Subscriber

    controller = "builtin-dynamic" if args.dynabarn else "builtin-robust"
    opts = StackOptions.for_controller(controller, world=args.world, seed=args.seed, dynabarn=args.dynabarn,
                                       rules=BarnRules())
    poses: dict[str, list[tuple[float, float, float, float]]] = {"odom": [], "belief": [], "truth": []}
    scans: list[tuple[float, float, float, np.ndarray]] = []
    done = threading.Event()

    def observe(ctx: Any) -> Any:
        # What the mapper reads (its inputs at their stack names), what it says, and the truth.
        subs = {"odom": Subscriber(ctx, "/odom", M.Odometry, queue_size=4096),
                "belief": Subscriber(ctx, LOCALIZED_POSE_TOPIC, M.Odometry, queue_size=4096),
                "truth": Subscriber(ctx, GROUND_TRUTH_TOPIC, M.Odometry, queue_size=4096),
                "scan": Subscriber(ctx, "/scan", M.LaserScan, queue_size=1024)}

        def drain() -> None:
            while not done.is_set():
                for name, sub in subs.items():
                    for msg in sub.take():
                        stamp = msg.header.stamp.to_sec()
                        if name == "scan":
                            scans.append((stamp, msg.angle_min, msg.angle_increment,
                                          np.asarray(msg.ranges, dtype=np.float32).copy()))
                        else:
                            p = msg.pose.pose
                            poses[name].append((stamp, p.position.x, p.position.y, p.orientation.yaw()))
                time.sleep(0.005)

        worker = threading.Thread(target=drain, name="pose-replay-record", daemon=True)
        worker.start()

        def stop() -> None:
            done.set()
            worker.join(timeout=5.0)
            for sub in subs.values():
                sub.close()
        return stop

    entry = opts.entry()
    result = run_episode_process(entry, opts, png_path=args.output.with_suffix(".png"), observer=observe)
    print(f"world {args.world} seed {args.seed}: {result.reason} after {result.time_s:.1f} s")
    if not scans:
        print("no scans recorded")
        return 1
    np.savez_compressed(args.output, dynabarn=args.dynabarn, world=args.world, seed=args.seed,
                        **{name: np.asarray(rows, dtype=float) for name, rows in poses.items()},
                        scan_t=np.array([s[0] for s in scans]), scan_amin=np.array([s[1] for s in scans]),
                        scan_ainc=np.array([s[2] for s in scans]), scan_ranges=np.stack([s[3] for s in scans]))
    print(f"wrote {args.output}: {len(scans)} scans, {len(poses['odom'])} odometry, {len(poses['belief'])} beliefs")
    return 0


def _at(rows: np.ndarray, stamp: float) -> np.ndarray:
    """The last row (stamp, x, y, yaw) at or before ``stamp`` (the first if none)."""
    i = bisect.bisect_right(rows[:, 0], stamp + 1e-9) - 1
    return rows[max(i, 0)]


def replay(args: argparse.Namespace) -> int:
    from emos.actors.nav.components.local_mapper import memory_of
    from emos.actors.nav.controllers.sensors import LaserScan2D
    from emos.actors.sim.jackal import JACKAL_LASER
    from emos.geometry import PoseHistory
    from emos.tools.barn.stack import StackOptions, build_system

    z = np.load(args.trace)
    dynabarn = bool(z["dynabarn"])
    # The mapper exactly as the stack configures it (bounds, resolution, mount, forgetting).
    _, (mapper, *_) = build_system(StackOptions.for_controller("builtin-dynamic" if dynabarn else "builtin-robust",
                                                               world=int(z["world"]), dynabarn=dynabarn))
    memory = memory_of(mapper.config)
    if args.match_margin is not None:  # a matcher setting to try against the stack's
        memory.match_margin = args.match_margin
    odom, belief, truth = z["odom"], z["belief"], z["truth"]
    n = len(z["scan_t"]) if args.scans is None else min(args.scans, len(z["scan_t"]))
    t0, next_print = float(z["scan_t"][0]), float(z["scan_t"][0])
    print("pose errors against the truth (m), x and y")
    print(f"{'t s':>6}  {'replayed':>15}  {'recorded belief':>15}  {'odometry':>15}")
    worst = 0.0
    odometry = PoseHistory()  # the odometry at each scan's stamp, looked up as the LocalMapper does
    fed = 0
    for k in range(n):
        stamp = float(z["scan_t"][k])
        while fed < len(odom) and odom[fed, 0] <= stamp + 1e-9:
            odometry.add(float(odom[fed, 0]), odom[fed, 1:4])
            fed += 1
        scan = LaserScan2D(ranges=z["scan_ranges"][k], angle_min=float(z["scan_amin"][k]),
                           angle_increment=float(z["scan_ainc"][k]), range_min=JACKAL_LASER.range_min,
                           range_max=JACKAL_LASER.range_max)
        o, t = odometry.at(stamp), _at(truth, stamp)
        assert o is not None  # the recording has odometry from its first scan on
        pose = memory.update(scan, o)
        worst = max(worst, float(np.hypot(pose[0] - t[1], pose[1] - t[2])))
        if stamp >= next_print or k == n - 1:
            b = _at(belief, stamp)
            cells = [f"{a - t[1]:+7.3f} {c - t[2]:+7.3f}" for a, c in ((pose[0], pose[1]), (b[1], b[2]), (o[0], o[1]))]
            if abs(b[0] - stamp) > 1e-6:  # the trial ended before the stack's belief of this scan was recorded
                cells[1] = f"{'-':>7} {'-':>7}"
            print(f"{stamp - t0:6.1f}  " + "  ".join(cells))
            next_print = stamp + args.every
    print(f"largest replayed pose error {worst:.3f} m over {n} scans")
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    rec = sub.add_parser("record", help="run one process-mode trial and keep the mapper's inputs, belief and truth")
    rec.add_argument("--world", type=int, required=True)
    rec.add_argument("--seed", type=int, required=True, help="the trial seed (emos bench barn's logs name it)")
    rec.add_argument("--dynabarn", action="store_true", help="a world of the moving-obstacle set (else BARN)")
    rec.add_argument("-o", "--output", type=Path, required=True, help="the .npz file (a .png of the run beside it)")
    rep = sub.add_parser("replay", help="feed a recorded trial through the mapper and print its pose error")
    rep.add_argument("trace", type=Path)
    rep.add_argument("--scans", type=int, default=None, help="only the first N scans")
    rep.add_argument("--match-margin", type=float, default=None,
                     help="try another MemoryMapper.match_margin (the stack's: 0.01)")
    rep.add_argument("--every", type=float, default=5.0, help="print every this many simulated seconds")
    args = parser.parse_args()
    if args.command == "record" and args.output.suffix != ".npz":
        parser.error(f"--output {args.output}: expected a .npz file")
    return record(args) if args.command == "record" else replay(args)


if __name__ == "__main__":
    raise SystemExit(main())
