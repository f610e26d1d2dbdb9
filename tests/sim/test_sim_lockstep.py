"""Lockstep: the simulator waits for its consumers, so load changes wall time only."""
from __future__ import annotations

import subprocess
import sys
import time

import numpy as np
import pytest

from emos import msgs as M
from emos.transport.pubsub import Subscriber
from tests.runtime.helpers import SystemUnderTest, kill_leftover_systems, wait_until

pytest.importorskip("pybullet", reason="pybullet (emos[sim]) is not installed")

pytestmark = [pytest.mark.sim, pytest.mark.process]


@pytest.fixture(autouse=True)
def _no_system_outlives_its_test():
    yield
    kill_leftover_systems()


# A feedback controller on simulated time: it steers toward a point from the odometry it sees,
# so any difference in what it saw (a late odometry message, a command applied a tick late)
# changes the trajectory. LOAD_S adds a random delay to every step (a loaded machine).
RECIPE = """
import random
from emos.actors.sim import Simulator, SimulatorConfig
from emos.core import clock
from emos.config import BaseComponentConfig

class Driver(BaseComponent):
    def _execution_step(self):
        t = clock.now()
        while os.path.exists(os.environ["PAUSE_FLAG"]):
            open(os.environ["PAUSE_FLAG"] + ".held", "a").close()  # the test waits for this
            time.sleep(0.02)
        load = float(os.environ.get("LOAD_S", "0"))
        if load:
            time.sleep(random.random() * load)
        odom = self.get_input("/odom")
        if odom is None:
            vx = omega = 0.0
            x = y = yaw = float("nan")
        else:
            p = odom.pose.pose
            x, y, yaw = p.position.x, p.position.y, p.orientation.yaw()
            heading = np.arctan2(2.5 - y, 3.0 - x)
            omega = float(np.clip(2.0 * np.angle(np.exp(1j * (heading - yaw))), -1.5, 1.5))
            vx = float(min(0.8, np.hypot(3.0 - x, 2.5 - y)))
        self.publish("/cmd_vel", M.Twist(linear=M.Vector3(x=vx), angular=M.Vector3(z=omega)))
        age = self.input_age("/odom")  # on simulated time: the same however loaded the machine
        with open(os.environ["TRACE"], "a") as f:
            f.write(f"{t:.3f} {x!r} {y!r} {yaw!r} {vx!r} {omega!r} {age if age is None else round(age, 6)!r}\\n")
        self.health_status.set_healthy()

class ScanLog(BaseComponent):
    '''Event-triggered on /scan: in lockstep it answers a tick only after handling its scans.'''
    def custom_on_activate(self):
        self.create_timer(0.25, self._timer_tick)  # a use_sim_time node's timers run on /clock

    def _timer_tick(self):
        with open(os.environ["TICKS"], "a") as f:
            f.write(f"{clock.now():.3f}\\n")

    def _execution_step(self, msg=None, topic=None):
        if msg is not None:
            with open(os.environ["SCANS"], "a") as f:
                f.write(f"{msg.header.stamp.to_sec():.3f} {float(np.min(msg.ranges))!r}\\n")
        self.health_status.set_healthy()

scan_log = ScanLog("scan_log", trigger=Topic(name="/scan", msg_type="LaserScan"),
                   config=BaseComponentConfig(use_sim_time=True))
driver = Driver("driver", inputs=[Topic(name="/odom", msg_type="Odometry")],
                outputs=[Topic(name="/cmd_vel", msg_type="Twist")],
                config=BaseComponentConfig(loop_rate=10.0, use_sim_time=True))
sim = Simulator("sim", config=SimulatorConfig(world="house", robot="jackal", clock_mode="lockstep",
                                             lockstep_consumers=["driver", "scan_log"], clock_rate=20.0, scan_rate=5.0))
launcher = Launcher(multi_processing=True, heartbeat_timeout=30.0)
launcher.add_pkg(components=[sim, driver, scan_log])
launcher.bringup()
"""

SIM_SECONDS = 6.0


def _run(tmp_path, name: str, load_s: float, pause_check: bool = False) -> list[str]:
    work = tmp_path / name
    work.mkdir()
    trace, pause, scans, ticks = work / "trace.txt", work / "pause", work / "scans.txt", work / "ticks.txt"
    env = {"TRACE": str(trace), "PAUSE_FLAG": str(pause), "LOAD_S": str(load_s), "SCANS": str(scans), "TICKS": str(ticks)}
    system = SystemUnderTest(work, RECIPE, env=env).wait_up(components=["sim", "driver", "scan_log"], timeout=60)
    clock = Subscriber(system.ctx, "/clock", M.Clock, queue_size=1000)

    def sim_time() -> float:
        msg = clock.latest()
        if msg is not None:
            sim_time.last = msg.clock.to_sec()
        return sim_time.last

    sim_time.last = -1.0
    try:
        if pause_check:
            wait_until(lambda: sim_time() > 1.0, 60, what="simulated time past 1 s")
            pause.touch()
            held = work / "pause.held"
            wait_until(held.exists, 60, what="the driver held in a step")  # and so is the simulator
            frozen = sim_time()
            time.sleep(1.5)
            assert sim_time() == frozen, "the sim clock advanced while a lockstep consumer had not answered"
            pause.unlink()
            wait_until(lambda: sim_time() > frozen + 0.5, 30, what="the clock to move on after the answer")
        wait_until(lambda: sim_time() >= SIM_SECONDS, 120, what=f"{SIM_SECONDS} simulated seconds")
    finally:
        clock.close()
        assert system.stop() == 0
    def upto(path):
        return [line for line in path.read_text().splitlines() if float(line.split()[0]) <= SIM_SECONDS - 0.5]

    return upto(trace), upto(scans), upto(ticks)


def test_lockstep_waits_for_consumers_and_load_changes_nothing(tmp_path):
    quiet, quiet_scans, quiet_ticks = _run(tmp_path, "quiet", load_s=0.0, pause_check=True)
    # The same run on a loaded machine: a CPU hog beside it and random delays in every step.
    hog = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        loaded, loaded_scans, loaded_ticks = _run(tmp_path, "loaded", load_s=0.03)
    finally:
        hog.kill()
        hog.wait()
    assert len(quiet) >= 50  # 10 Hz steps over 5.5 simulated seconds
    times = [float(line.split()[0]) for line in quiet]
    assert times == sorted(times) and times[1] - times[0] == pytest.approx(0.1)
    assert float(quiet[-1].split()[1]) > 1.5  # the robot did drive toward (3, 2.5)
    assert loaded == quiet
    # The event-triggered consumer handled every scan (5 Hz, none lost), the same ones both times.
    stamps = [float(line.split()[0]) for line in quiet_scans]
    assert len(stamps) >= 25 and np.allclose(np.diff(stamps), 0.2)
    assert loaded_scans == quiet_scans
    # Its 4 Hz timer fired every 0.25 simulated s, also while the clock stood still (the pause):
    # a wall-clock timer fires there at a frozen time, and under load at another rate.
    beats = [float(line) for line in quiet_ticks]
    assert len(beats) >= 18 and np.allclose(np.diff(beats), 0.25), beats
    assert loaded_ticks == quiet_ticks
