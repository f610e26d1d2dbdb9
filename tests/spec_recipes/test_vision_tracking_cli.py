"""The vision-tracking page's "Trigger the Following Action" step, on the port
(recipes/vision_tracking_rgb.py): the recipe alone leaves the robot still; the page's
``ros2 action send_goal /my_controller/track_vision_target ... "{label: 'person'}"`` is
``emos action send_goal my_controller track_vision_target '{"label": "person"}'``, which prints
the controller's feedback while the robot turns with the walking person, and Ctrl-C cancels
the goal. (How well it follows is tests/nav/components/test_vision_tracking_recipes.py.)"""
from __future__ import annotations

import math
import signal
import subprocess
import sys
import time

import pytest

from emos import msgs as M
from tests.runtime.helpers import REPO, SystemUnderTest, ctrl_c_as_at_a_terminal, wait_until

pytestmark = [pytest.mark.sim, pytest.mark.process]


def _yaw(o) -> tuple[float, float]:
    q = o.pose.pose.orientation
    t = o.header.stamp.sec + o.header.stamp.nanosec * 1e-9
    return t, math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))


def test_send_goal_from_the_cli_starts_the_following_and_ctrl_c_cancels_it(tmp_path):
    from emos.transport.pubsub import Subscriber

    system = SystemUnderTest(tmp_path, (REPO / "recipes" / "vision_tracking_rgb.py").read_text(), env={"PYTHONPATH": str(REPO)})
    cli = None
    try:
        system.wait_up(components=["my_controller", "detection_component", "sim"], timeout=120)
        odom = Subscriber(system.ctx, "/odom", M.Odometry, queue_size=1000)
        samples: list[tuple[float, float]] = []

        def simulated(seconds: float) -> bool:
            samples.extend(_yaw(o) for o in odom.take())
            return bool(samples) and samples[-1][0] - samples[0][0] > seconds

        # No goal yet: the person walks, the robot stays put (3 simulated seconds).
        wait_until(lambda: simulated(3.0), 120, what="3 simulated seconds of odometry")
        still = max(abs(math.remainder(y - samples[0][1], math.tau)) for _, y in samples)
        assert still < 0.02, f"the robot turned {still:.3f} rad before any goal"

        cli = subprocess.Popen([sys.executable, "-m", "emos", "action", "send_goal", "--run", system.ctx.run_id,
                                "my_controller", "track_vision_target", '{"label": "person"}'],
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, preexec_fn=ctrl_c_as_at_a_terminal)
        yaw0 = samples[-1][1]

        def turned() -> bool:
            samples.extend(_yaw(o) for o in odom.take())
            return abs(math.remainder(samples[-1][1] - yaw0, math.tau)) > 0.2

        wait_until(turned, 180, what="the robot turning with the person after the goal")
        odom.close()
        time.sleep(0.5)
        cli.send_signal(signal.SIGINT)  # Ctrl-C
        out, _ = cli.communicate(timeout=60)
        assert cli.returncode == 130, out[-2000:]
        assert '"target_visible": true' in out, out[-2000:]  # feedback as it came
        assert "cancel acknowledged by /my_controller/track_vision_target" in out and "goal finished: canceled" in out, out[-2000:]
    finally:
        if cli is not None and cli.poll() is None:
            cli.kill()
            cli.wait()
        system.stop()
