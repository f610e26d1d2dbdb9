"""``emos bench sim``: how many times faster than real time the Jackal world steps.

The world: BARN world 1 (about 230 obstacles), the Jackal at the BARN start driving a slow
circle, physics ticks of 10 ms, lock-step clock (no pacing), pinned to one CPU core.

Default (the realistic BARN configuration): the ``jackal-barn`` robot (skid-steer drive,
chassis + wheels collision shape), its laser (720 beams over 270 deg, 30 m, 50 Hz, noise) and
wheel + IMU odometry at 50 Hz. ``--ideal``: the kinematic box Jackal, a 720-beam 360 deg
lidar at 20 Hz and ground-truth odometry at 50 Hz (the configuration measured before).
``--robot jackal-wheeled``: the pybullet wheeled Jackal with the realistic sensors.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--duration", type=float, default=60.0, help="simulated seconds to run (default 60)")
    parser.add_argument("--world", type=int, default=1, help="BARN world index to use (default 1)")
    parser.add_argument("--no-pin", action="store_true", help="do not pin the process to one CPU core")
    parser.add_argument("--json", action="store_true", help='print only {"realtime_factor": x}')
    parser.add_argument("--worlds-file", default=None, help="BARN worlds.json (default: ../shared/benchmarks/barn/worlds.json)")
    parser.add_argument("--ideal", action="store_true",
                        help="the kinematic box Jackal, 360 deg lidar at 20 Hz, ground-truth odometry (the old default)")
    parser.add_argument("--robot", default=None, choices=("jackal-barn", "jackal-wheeled"),
                        help="robot of the realistic configuration (default jackal-barn)")
    parser.add_argument("--component", action="store_true",
                        help="measure the Simulator component in lockstep with a consumer (own processes; "
                             "demo house, not BARN); --duration is then wall seconds (default 20)")
    parser.add_argument("--camera", action="store_true", help="with --component: also render a 320x240 camera at 10 Hz")


def measure(duration: float = 60.0, world_idx: int = 1, worlds_file: str | None = None, ideal: bool = False,
            robot_name: str = "jackal-barn") -> dict:
    from emos.actors.sim.barn_worlds import BARN_START
    from emos.actors.sim.builders import from_barn
    from emos.actors.sim.clock import ClockMode, SimClock
    from emos.actors.sim.jackal import JACKAL_LASER
    from emos.actors.sim.sensors import Lidar, LidarConfig, Odometry, OdometryConfig, WheelImuOdometry

    world = from_barn(world_idx, worlds_file, clock=SimClock(dt=0.01, mode=ClockMode.LOCKSTEP))
    try:
        if ideal:
            robot = world.add_robot("jackal", BARN_START)
            lidar = world.add_sensor(Lidar(robot, LidarConfig(fov_deg=360.0, beams=720, rate_hz=20.0)))
            world.add_sensor(Odometry(robot, OdometryConfig(rate_hz=50.0)))
        else:
            robot = world.add_robot(robot_name, BARN_START)
            lidar = world.add_sensor(Lidar(robot, JACKAL_LASER))
            world.add_sensor(WheelImuOdometry(robot))
        # The ideal Jackal: a 0.6 m circle. A skid-steer base turns less than commanded (the
        # wheeled one at small turn rates less than half), so it is asked for a tighter one.
        command = (0.3, 0.0, 0.5) if ideal else (0.2, 0.0, 1.0)
        world.step()  # bake the obstacle mesh outside the timed part
        ticks = int(round(duration / world.clock.dt))
        scans = 0
        t0 = time.perf_counter()
        for _ in range(ticks):
            # A slow circle in the free area around the start, commanded at every tick (as a
            # controller would: the realistic bases stop after 0.25 s without a command).
            robot.command(*command)
            scans += sum(1 for sensor, _ in world.step() if sensor is lidar)
        wall = time.perf_counter() - t0
        if robot.collided:
            raise RuntimeError("bench sim: the robot collided; the benchmark world is not what it should be")
        return {"realtime_factor": duration / wall, "wall_s": wall, "sim_s": duration, "ticks": ticks,
                "scans": scans, "obstacles": len(world.shapes), "robot": robot.spec.name, "drive": robot.drive.name}
    finally:
        world.close()


def run(args: argparse.Namespace) -> int:
    if args.component:
        from .sim_component import measure as measure_component
        from .sim_component import print_table

        duration = 20.0 if args.duration == 60.0 else args.duration
        result = measure_component(duration, camera=args.camera)
        if args.json:
            print(json.dumps({"realtime_factor": round(result["realtime_factor"], 2),
                              "rates_per_wall_s": {k: round(v["per_wall_s"], 2) for k, v in result["rates"].items()}}))
        else:
            print_table(result)
        return 0
    pinned = None
    if not args.no_pin and hasattr(os, "sched_setaffinity"):
        pinned = min(os.sched_getaffinity(0))
        os.sched_setaffinity(0, {pinned})
    if args.ideal and args.robot:
        print("emos bench sim: --robot chooses the robot of the realistic configuration; it cannot go with --ideal",
              file=sys.stderr)
        return 2
    result = measure(args.duration, args.world, args.worlds_file, ideal=args.ideal, robot_name=args.robot or "jackal-barn")
    if args.json:
        print(json.dumps({"realtime_factor": round(result["realtime_factor"], 2)}))
        return 0
    if args.ideal:
        print("EMOS simulation speed, --ideal (kinematic Jackal, 720-beam 360 deg lidar @ 20 Hz, true odometry @ 50 Hz, "
              "10 ms ticks, lock-step)")
    else:
        print(f"EMOS simulation speed, realistic ({result['robot']}: {result['drive']} drive, 720-beam 270 deg laser "
              "@ 50 Hz, wheel+IMU odometry @ 50 Hz, 10 ms ticks, lock-step)")
    print(f"  world               BARN {args.world} ({result['obstacles']} obstacles)")
    print(f"  cpu                 {'core ' + str(pinned) if pinned is not None else 'not pinned'}")
    print(f"  simulated           {result['sim_s']:.1f} s ({result['ticks']} ticks, {result['scans']} scans)")
    print(f"  wall                {result['wall_s']:.2f} s")
    print(f"  realtime factor     {result['realtime_factor']:.1f}x")
    return 0
