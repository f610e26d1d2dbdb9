"""The Vision detector under ``emos run --lockstep`` (real processes: the Simulator's camera and
the Vision component with its on-board HOG detector). Its node answers a tick only once the
worker thread has detected the frame that tick brought (``SimTimeDriver.hold_ticks_for``), so
every frame is detected however slow the detector is next to the simulator. Before, the
simulator ran on while the worker was busy and the worker took the newest frame when done: at
400 x 300 and 20 frames per simulated second most frames were never seen, and how many depended
on the machine."""
from __future__ import annotations

import time

import pytest

from emos import msgs as M
from tests.runtime.helpers import REPO, SystemUnderTest, wait_until

pytestmark = [pytest.mark.process, pytest.mark.sim]

RECIPE = '''
from emos.actors.agents import Vision, VisionConfig
from emos.actors.sim import Simulator, SimulatorConfig

image = Topic(name="/camera/image", msg_type="Image")
sim = Simulator("sim", config=SimulatorConfig(world="house", camera_rate=20.0, camera_width=400, camera_height=300))
sim.outputs(camera=image)
vision = Vision(inputs=[image], outputs=[Topic(name="/detections", msg_type="Detections")], trigger=image,
                config=VisionConfig(enable_local_classifier=True, input_width=400, input_height=300),
                component_name="detector")
launcher = Launcher()
launcher.add_pkg(components=[sim, vision])
launcher.bringup()
'''


def _stamp(msg) -> int:
    return msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec


def test_every_camera_frame_is_detected_before_the_simulator_goes_on(tmp_path):
    from emos.transport.pubsub import Subscriber

    system = SystemUnderTest(tmp_path, RECIPE, env={"PYTHONPATH": str(REPO)}, args=["--lockstep"])
    try:
        system.wait_up(components=["sim", "detector"], timeout=120)
        assert "lockstep: the simulator waits every tick for detector" in system.output(), system.output()[-3000:]
        frames = Subscriber(system.ctx, "/camera/image", M.Image, queue_size=1000)
        detections = Subscriber(system.ctx, "/detections", M.Detections, queue_size=1000)
        framed: list[int] = []
        detected: set[int] = set()

        def seen_enough() -> bool:
            framed.extend(_stamp(m) for m in frames.take())
            detected.update(_stamp(m) for m in detections.take())
            return len(framed) >= 40  # 2 simulated seconds of frames

        wait_until(seen_enough, timeout=300, interval=0.05, what="40 camera frames")
        # The last frame's detection may still be on its way; every earlier one was published
        # before the tick after it was answered. (A bounded look, not a wait that must succeed:
        # with frames dropped, the one looked for may never come.)
        deadline = time.monotonic() + 30
        while framed[-2] not in detected and time.monotonic() < deadline:
            time.sleep(0.05)
            detected.update(_stamp(m) for m in detections.take())
        frames.close()
        detections.close()
        missed = [t for t in framed[:-1] if t not in detected]
        assert not missed, f"{len(missed)} of {len(framed) - 1} frames never detected (first stamps {missed[:5]})"
    finally:
        assert system.stop() == 0, system.output()[-3000:]
