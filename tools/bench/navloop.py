"""``emos bench navloop``: scan in, motor command out, through the navigation processes.

A real system under the supervisor (``emos run``): LocalMapper (Event: maps each scan as it
arrives), Controller (Event: computes on each local map; ``--algorithm``) and DriveManager
(Event: passes each command through its safety zones and limits), each in its own process.
This process plays the robot: it publishes odometry and a 720-beam LaserScan at ``--rate`` Hz
and a path to follow, and listens to the DriveManager's ``/cmd_vel``. Commands are
TwistStamped and keep the stamp of the scan they come from (the Controller stamps its command
with its input's time, the DriveManager keeps it), so each command is matched to its scan
exactly. Latency = command received here - scan stamp. A cycle is *missed* when no command
for a scan arrived within one period (before the next scan).
"""
from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

RECIPE = """
from emos import Launcher, Topic
from emos.actors.nav import MapConfig
from emos.actors.nav.components import (Controller, ControllerConfig, DriveManager, DriveManagerConfig, LocalMapper,
    LocalMapperConfig)

scan = Topic(name="/scan", msg_type="LaserScan")
grid = Topic(name="/local_map/occupancy_layer", msg_type="OccupancyGrid")
control = Topic(name="/control", msg_type="TwistStamped")
mapper = LocalMapper(component_name="mapper", config=LocalMapperConfig(map_params=MapConfig(width=3.0, height=3.0, resolution=0.05)))
mapper.run_type = "Event"
controller = Controller(component_name="controller", config=ControllerConfig(algorithm=ALGORITHM, use_direct_sensor=False))
controller.outputs(command=control)
controller.run_type = "Event"
driver = DriveManager(component_name="driver", config=DriveManagerConfig(critical_zone_distance=0.05, slowdown_zone_distance=0.3))
driver.inputs(command=control)
driver.outputs(robot_command=Topic(name="/cmd_vel", msg_type="TwistStamped"))
launcher = Launcher(multi_processing=True)
launcher.kompass(components=[mapper, controller, driver], multiprocessing=True)
launcher.bringup()
"""

COMPONENTS = ("mapper", "controller", "driver")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--duration", type=float, default=20.0, help="measured seconds (the target is sustained 20 Hz over 60 s)")
    parser.add_argument("--rate", type=float, default=20.0, help="scan rate in Hz")
    parser.add_argument("--algorithm", default="DWA", help="controller algorithm (a ControllersID name)")
    parser.add_argument("--warmup", type=float, default=3.0, help="seconds of scans before measuring")
    parser.add_argument("--json", action="store_true", help="print the machine-readable result only")


def _scan(ranges: np.ndarray) -> Any:
    from emos import msgs as M

    return M.LaserScan(header=M.Header(stamp=M.Time.now(), frame_id="scan"), angle_min=-math.pi, angle_max=math.pi,
                       angle_increment=2 * math.pi / len(ranges), range_min=0.05, range_max=10.0, ranges=ranges)


def _room_scan(beams: int = 720) -> np.ndarray:
    """A corridor 2 m wide with a post 1.5 m ahead, off the path: obstacles in every map."""
    a = -math.pi + np.arange(beams) * 2 * math.pi / beams
    with np.errstate(divide="ignore"):
        side = np.where(np.sin(a) != 0, 1.0 / np.abs(np.sin(a)), np.inf)
    r = np.minimum(side, 8.0)
    post = np.abs(a - math.atan2(0.4, 1.5)) < 0.08
    r[post] = np.minimum(r[post], math.hypot(1.5, 0.4) - 0.1)
    return r.astype(np.float32)


def measure(duration: float = 20.0, rate: float = 20.0, algorithm: str = "DWA", warmup: float = 3.0) -> dict[str, Any]:
    from emos import msgs as M
    from emos.actors.nav.components.convert import path_msg
    from emos.actors.nav.controllers import ControllersID
    from emos.core.rpc import RpcClient
    from emos.supervisor.launched import wait_active, wait_run_dir
    from emos.transport.context import RunContext
    from emos.transport.pubsub import Publisher, Subscriber

    algorithm = ControllersID.from_any(algorithm).value
    if not (rate > 0 and duration > 0):
        raise ValueError(f"bench navloop: --rate and --duration must be > 0, got {rate}, {duration}")
    with tempfile.TemporaryDirectory(prefix="emos-bench-navloop-") as tmp:
        script = Path(tmp) / "recipe.py"
        script.write_text(f"ALGORITHM = {algorithm!r}\n" + RECIPE)
        log_path = Path(tmp) / "system.log"
        with open(log_path, "wb") as log:  # the child writes to its own copy of the descriptor
            proc = subprocess.Popen([sys.executable, "-m", "emos", "run", str(script)], stdout=log, stderr=subprocess.STDOUT, cwd=tmp)
        pubs: list = []
        sub = None
        try:
            run_dir = wait_run_dir(proc, log_path, "bench navloop")
            ctx = RunContext(run_dir.name, run_dir, owner=False)
            rpc = RpcClient(run_dir / "supervisor.sock")
            wait_active(rpc, proc, log_path, COMPONENTS, "bench navloop")
            rpc.close()
            scan_pub = Publisher(ctx, "/scan", M.LaserScan, publisher_id="bench_scan")
            odom_pub = Publisher(ctx, "/odom", M.Odometry, publisher_id="bench_odom")
            plan_pub = Publisher(ctx, "/plan", M.Path, publisher_id="bench_plan")
            pubs = [scan_pub, odom_pub, plan_pub]
            sub = Subscriber(ctx, "/cmd_vel", M.TwistStamped, queue_size=64)
            ranges = _room_scan()
            path = np.c_[np.linspace(0, 6, 121), np.zeros(121), np.zeros(121)]
            plan = path_msg(path, "map")
            odom = M.Odometry()
            odom.pose.pose.orientation.w = 1.0
            period = 1.0 / rate
            sent: dict[tuple[int, int], float] = {}
            arrived: dict[tuple[int, int], float] = {}
            t_start = time.monotonic()
            next_t = t_start
            k = 0
            measure_from = t_start + warmup
            end = measure_from + duration
            while True:
                now = time.monotonic()
                if now >= end:
                    break
                if now >= next_t:
                    if k % int(max(1, rate)) == 0:
                        plan.header.stamp = M.Time.now()
                        plan_pub.publish(plan)
                    odom.header.stamp = M.Time.now()
                    odom_pub.publish(odom)
                    msg = _scan(ranges)
                    scan_pub.publish(msg)
                    if now >= measure_from:
                        sent[(msg.header.stamp.sec, msg.header.stamp.nanosec)] = msg.header.stamp.to_sec()
                    k += 1
                    next_t += period
                    if next_t < now:  # we fell behind (load): keep the schedule, do not burst
                        next_t = now + period
                for m in sub.take():
                    key = (m.header.stamp.sec, m.header.stamp.nanosec)
                    arrived.setdefault(key, time.time())
                time.sleep(max(0.0, min(next_t - time.monotonic(), 0.002)))
            settle = time.monotonic() + 0.5
            while time.monotonic() < settle:
                for m in sub.take():
                    arrived.setdefault((m.header.stamp.sec, m.header.stamp.nanosec), time.time())
                time.sleep(0.002)
        finally:
            for p in pubs:
                p.close()
            if sub is not None:
                sub.close()
            proc.terminate()
            try:
                proc.wait(30)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
    lat = np.array([(arrived[key] - t0) * 1e3 for key, t0 in sent.items() if key in arrived])
    missed = sum(1 for key, t0 in sent.items() if key not in arrived or arrived[key] - t0 > period)
    if lat.size == 0:
        raise RuntimeError(f"bench navloop: no command matched any scan ({len(sent)} scans sent); system log:\n{log_path}")
    return {
        "scan_to_cmd_ms": {"p50": round(float(np.percentile(lat, 50)), 2), "p95": round(float(np.percentile(lat, 95)), 2)},
        "missed_cycles": int(missed), "cycles": len(sent),
        "max_ms": round(float(lat.max()), 2), "rate_hz": rate, "duration_s": duration, "algorithm": algorithm,
    }


def run(args: argparse.Namespace) -> int:
    result = measure(args.duration, args.rate, args.algorithm, args.warmup)
    if args.json:
        print(json.dumps({k: result[k] for k in ("scan_to_cmd_ms", "missed_cycles", "cycles")} | {
            "max_ms": result["max_ms"], "rate_hz": result["rate_hz"], "duration_s": result["duration_s"], "algorithm": result["algorithm"]}))
        return 0
    lat = result["scan_to_cmd_ms"]
    print(f"EMOS navigation loop: 720-beam scan -> LocalMapper -> Controller ({result['algorithm']}) -> DriveManager -> /cmd_vel")
    print(f"  {result['cycles']} cycles at {result['rate_hz']:g} Hz over {result['duration_s']:g} s (own processes)")
    print(f"  scan to command   p50 {lat['p50']:.2f} ms   p95 {lat['p95']:.2f} ms   max {result['max_ms']:.2f} ms")
    print(f"  missed cycles     {result['missed_cycles']} (no command within one period)")
    return 0
