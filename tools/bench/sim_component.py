"""``emos bench sim --component``: the Simulator component in lockstep with a consumer.

Runs a real recipe under the supervisor (``emos run``): the Simulator in the demo house
(Jackal, odometry 50 Hz, 360-beam scan 10 Hz, optionally a 320x240 camera at 10 Hz, /clock
at 50 Hz, lockstep) and a ``use_sim_time`` consumer at 10 Hz that wanders on the scan: it
reads odometry and scan each step and publishes a Twist. This process subscribes to the
topics and reports, over the measured window, the real-time factor (simulated seconds per
wall second) and each topic's rate in simulated and in wall time.
"""
from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

RECIPE = """
import numpy as np
from emos import BaseComponent, Launcher, Topic
from emos import msgs as M
from emos.actors.sim import Simulator, SimulatorConfig
from emos.config import BaseComponentConfig

class Wanderer(BaseComponent):
    def _execution_step(self):
        scan = self.get_input("/scan")
        vx, omega = 0.0, 0.0
        if scan is not None:
            r = np.asarray(scan.ranges)
            n = len(r)
            front = float(np.min(r[np.r_[0:n // 12, n - n // 12:n]]))
            vx, omega = (0.5, 0.0) if front > 0.8 else (0.0, 1.0)
        self.publish("/cmd_vel", M.Twist(linear=M.Vector3(x=vx), angular=M.Vector3(z=omega)))
        self.health_status.set_healthy()

wanderer = Wanderer("wanderer", inputs=[Topic(name="/scan", msg_type="LaserScan"), Topic(name="/odom", msg_type="Odometry")],
                    outputs=[Topic(name="/cmd_vel", msg_type="Twist")],
                    config=BaseComponentConfig(loop_rate=10.0, use_sim_time=True))
sim = Simulator("sim", config=SimulatorConfig(world="house", robot="jackal", clock_mode="lockstep",
                                             lockstep_consumers=["wanderer"], scan_rate=10.0, odom_rate=50.0))
if CAMERA:
    sim.outputs(camera=Topic(name="/camera/image_raw", msg_type="Image"))
launcher = Launcher(multi_processing=True, heartbeat_timeout=30.0)
launcher.add_pkg(components=[sim, wanderer])
launcher.bringup()
"""

def measure(duration: float = 20.0, camera: bool = False, warmup: float = 3.0) -> dict[str, Any]:
    """Real-time factor and publish rates over ``duration`` wall seconds, from the Simulator's
    own counters (read through its control socket: a subscriber here could miss messages)."""
    from emos.core.control import ControlClient
    from emos.supervisor.launched import wait_run_dir
    from emos.transport.context import RunContext

    with tempfile.TemporaryDirectory(prefix="emos-bench-sim-") as tmp:
        script = Path(tmp) / "recipe.py"
        script.write_text(f"CAMERA = {camera!r}\n" + RECIPE)
        log_path = Path(tmp) / "system.log"
        with open(log_path, "wb") as log:  # the child writes to its own copy of the descriptor
            proc = subprocess.Popen([sys.executable, "-m", "emos", "run", str(script)], stdout=log, stderr=subprocess.STDOUT, cwd=tmp)
        try:
            run_dir = wait_run_dir(proc, log_path, "bench sim --component")
            ctx = RunContext(run_dir.name, run_dir, owner=False)
            sim = ControlClient("sim", ctx)

            def status() -> dict:
                try:
                    return sim.execute_method("sim_status") or {}
                except (OSError, ConnectionError):
                    return {}

            end = time.monotonic() + 60
            while status().get("sim_time", 0.0) <= 0.0:
                if time.monotonic() > end:
                    raise RuntimeError(f"bench sim --component: the simulation did not start:\n{log_path.read_text()}")
                time.sleep(0.1)
            time.sleep(warmup)
            before, wall0 = status(), time.monotonic()
            time.sleep(duration)
            after, wall1 = status(), time.monotonic()
        finally:
            proc.terminate()
            try:
                proc.wait(30)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
    wall, sim = wall1 - wall0, after["sim_time"] - before["sim_time"]
    rates = {}
    for key, count in after["published"].items():
        n = count - before["published"].get(key, 0)
        rates[key] = {"messages": n, "per_wall_s": n / wall, "per_sim_s": n / sim}
    return {"realtime_factor": sim / wall, "wall_s": wall, "sim_s": sim, "camera": camera, "rates": rates,
            "commands": after["commands"] - before["commands"],
            "lockstep_wait_share": (after["lockstep_wait_s"] - before["lockstep_wait_s"]) / wall}


def print_table(result: dict[str, Any]) -> None:
    print("EMOS Simulator component, lockstep with one use_sim_time consumer (emos run, own processes)")
    print(f"  world / robot       demo house / jackal{' + 320x240 camera @ 10 Hz' if result['camera'] else ''}")
    print(f"  measured            {result['wall_s']:.1f} s wall, {result['sim_s']:.1f} s simulated")
    print(f"  realtime factor     {result['realtime_factor']:.2f}x")
    print(f"  waiting for answers {100 * result['lockstep_wait_share']:.0f} % of the wall time")
    print(f"  commands received   {result['commands']}")
    print(f"  {'output':<20}{'msgs':>8}{'per wall s':>12}{'per sim s':>12}")
    for name, r in result["rates"].items():
        print(f"  {name:<20}{r['messages']:>8}{r['per_wall_s']:>12.1f}{r['per_sim_s']:>12.2f}")
