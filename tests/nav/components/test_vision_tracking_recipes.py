"""End to end: recipes/vision_tracking_{rgb,depth}.py make the simulated robot follow the walking
person (real processes: Simulator, Vision with the on-board people detector, Controller,
DriveManager). Only the test reads the ground truth: the robot's true odometry (no noise) and
the person's position on its path at the odometry's simulated time. The recipes run with
``emos run --lockstep``: the simulator waits every tick for the detector, the controllers and
the Controller's ``track_vision_target`` loop (stepped inside the Controller's ticks), so a busy
machine slows the run, not the robot's reactions (a realtime simulator at load 10 let the
person walk out of view before the detector had seen the frame)."""
from __future__ import annotations

import math
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from emos import msgs as M
from emos.actors.sim.person import Person
from tests.runtime.helpers import REPO, SystemUnderTest, ctrl_c_as_at_a_terminal

pytestmark = [pytest.mark.sim, pytest.mark.process]

FOLLOW_S = 20.0  # simulated seconds of following after the first detection (the person crosses ~3 times)
MIN_FOLLOW_S = 12.0  # at least this much, when the wall-clock backstop (a hang) ends the loop first


def _constants(source: str) -> tuple[tuple, tuple, float]:
    """The scene as the recipe defines it (spawn, person path and speed)."""
    spawn = eval(re.search(r"^ROBOT_SPAWN = (.*)$", source, re.M).group(1))
    path = eval(re.search(r"^PERSON_PATH = (.*)$", source, re.M).group(1))
    speed = float(re.search(r"^PERSON_SPEED = ([0-9.]+)", source, re.M).group(1))
    return spawn, path, speed


def _follow(tmp_path, recipe: str, detections: str) -> dict:
    from emos.transport.pubsub import Subscriber

    source = (REPO / "recipes" / recipe).read_text()
    spawn, path, speed = _constants(source)
    person = Person(waypoints=np.array(path), speed=speed, mode="pingpong")
    system = SystemUnderTest(tmp_path, source, env={"PYTHONPATH": str(REPO)}, args=["--lockstep"])
    cli = None
    try:
        # The spec starts the tracking from the command line (`ros2 action send_goal`): so do we.
        controller = re.search(r'Controller\(component_name="(\w+)"', source).group(1)
        system.wait_up(timeout=60, components=[controller])
        assert "lockstep: the simulator waits every tick for" in system.output(), system.output()[-3000:]
        cli = subprocess.Popen([sys.executable, "-m", "emos", "action", "send_goal", "--run", system.ctx.run_id,
                                controller, "track_vision_target", '{"label": "person"}'],
                               stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT, preexec_fn=ctrl_c_as_at_a_terminal)
        odom = Subscriber(system.ctx, "/odom", M.Odometry, queue_size=1000)
        dets = Subscriber(system.ctx, detections, M.Detections, queue_size=100)
        samples, seen, t_first = [], 0, None
        # The loop ends after FOLLOW_S simulated seconds; the wall deadline only bounds a hang (in
        # lockstep a loaded machine runs the simulation at a fraction of real time).
        wall_deadline = time.monotonic() + 300
        while time.monotonic() < wall_deadline:
            time.sleep(0.2)
            seen += sum("person" in list(d.labels) for d in dets.take())
            for o in odom.take():
                t = o.header.stamp.sec + o.header.stamp.nanosec * 1e-9
                q = o.pose.pose.orientation
                yaw = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))
                samples.append((t, o.pose.pose.position.x, o.pose.pose.position.y, yaw))
            if seen and t_first is None and samples:
                t_first = samples[-1][0]
            if t_first is not None and samples and samples[-1][0] - t_first > FOLLOW_S:
                break
        odom.close()
        dets.close()
        assert t_first is not None, f"no person detected on {detections}:\n{system.output()[-3000:]}"
        assert samples[-1][0] - t_first > MIN_FOLLOW_S, f"only {samples[-1][0] - t_first:.1f} s simulated after the first detection"
        rows = []
        for t, x, y, yaw in samples:
            if t < t_first + 4.0:  # time to turn to the person once seen
                continue
            px, py, _ = person.pose_at(t)
            bearing = math.atan2(py - y, px - x)
            static = math.atan2(py - spawn[1], px - spawn[0]) - spawn[2]  # where it would be, unfollowed
            rows.append((math.remainder(bearing - yaw, math.tau), static, math.hypot(px - x, py - y), yaw))
        a = np.array(rows)
        return {"err": np.abs(a[:, 0]), "static": np.abs(a[:, 1]), "dist": a[:, 2], "yaw": a[:, 3],
                "log": system.output()[-3000:]}
    finally:
        if cli is not None:
            cli.send_signal(signal.SIGINT)  # Ctrl-C: cancels the goal on the controller
            cli.wait(60)
        system.stop()


# swing: how far (rad) the person's bearing from the robot's start pose goes either side
@pytest.mark.parametrize("recipe,detections,swing", [("vision_tracking_rgb.py", "/detections", 0.45),
                                                     ("vision_tracking_depth.py", "/detections", 0.3)])
def test_robot_turns_with_the_walking_person_and_keeps_its_distance(tmp_path, recipe, detections, swing):
    r = _follow(tmp_path, recipe, detections)
    info = (f"bearing error mean {r['err'].mean():.2f} max {r['err'].max():.2f} rad; unfollowed bearing mean "
            f"{r['static'].mean():.2f}; distance {r['dist'].min():.2f}..{r['dist'].max():.2f} m; "
            f"yaw {r['yaw'].min():.2f}..{r['yaw'].max():.2f}\n{r['log']}")
    print(info.splitlines()[0])
    assert r["static"].max() > swing, info  # unfollowed, the person would go this far off-centre ...
    assert r["yaw"].max() - r["yaw"].min() > swing, info  # ... but the robot turned both ways with it,
    assert r["err"].max() < 0.35, info  # kept it well inside the view (half width ~0.66 rad),
    assert r["err"].mean() < 0.7 * r["static"].mean(), info  # nearer the centre than standing still would
    assert r["dist"].min() > 1.0 and r["dist"].max() < 3.5, info  # and at a bounded distance
    assert "lost" not in r["log"], info  # the tracking action never gave up


def test_start_vision_tracking_rejects_bad_definitions():
    from emos.actors.nav.components.track_target import StartVisionTracking

    with pytest.raises(ValueError, match="label"):
        StartVisionTracking(component_name="start", controller_name="controller", label="")
    with pytest.raises(ValueError, match="controller_name"):
        StartVisionTracking(component_name="start", controller_name="", label="person")
    with pytest.raises(ValueError, match="connect_timeout"):
        StartVisionTracking(component_name="start", controller_name="controller", label="person", connect_timeout=0)
    start = StartVisionTracking(component_name="start", controller_name="my_controller", label="person", search_timeout=5)
    assert start.action_name == "my_controller/track_vision_target"
    assert (start.goal.label, start.goal.search_timeout) == ("person", 5.0)
