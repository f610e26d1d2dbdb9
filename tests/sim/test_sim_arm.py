"""The table-top arm: SO-101 joint names, joint commands in, joint states and two cameras out."""
from __future__ import annotations

import io
import time

import numpy as np
import pytest

from emos import msgs as M
from emos.transport.pubsub import Publisher, Subscriber
from tests.runtime.helpers import SystemUnderTest, kill_leftover_systems, wait_until

pytest.importorskip("pybullet", reason="pybullet (emos[sim]) is not installed")

pytestmark = [pytest.mark.sim, pytest.mark.process]

JOINTS = ["Rotation", "Pitch", "Elbow", "Wrist_Pitch", "Wrist_Roll", "Jaw"]


@pytest.fixture(autouse=True)
def _no_system_outlives_its_test():
    yield
    kill_leftover_systems()


def test_arm_follows_joint_commands_and_publishes_states_and_cameras(tmp_path):
    system = SystemUnderTest(tmp_path, """
from emos.actors.sim import Simulator, SimulatorConfig
sim = Simulator("sim", config=SimulatorConfig(world="tabletop", camera_rate=4.0, camera_width=160, camera_height=120))
sim.inputs(joint_command=Topic(name="/isaac_joint_command", msg_type="JointState"))
sim.outputs(joint_states=Topic(name="/isaac_joint_states", msg_type="JointState"),
            camera=Topic(name="/front_camera/image_raw", msg_type="Image"),
            wrist_camera=Topic(name="/wrist_camera/image_raw/compressed", msg_type="CompressedImage"))
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[sim])
launcher.bringup()
""").wait_up(components=["sim"], timeout=60)
    states = Subscriber(system.ctx, "/isaac_joint_states", M.JointState, queue_size=100)
    front = Subscriber(system.ctx, "/front_camera/image_raw", M.Image, queue_size=10)
    wrist = Subscriber(system.ctx, "/wrist_camera/image_raw/compressed", M.CompressedImage, queue_size=10)
    command = Publisher(system.ctx, "/isaac_joint_command", M.JointState, publisher_id="test")

    def joints() -> dict[str, float]:
        msg = wait_until(states.latest, 20, what="joint states")
        return dict(zip(msg.name, msg.position.tolist()))

    try:
        first = wait_until(states.latest, 30, what="joint states")
        assert list(first.name) == JOINTS and first.header.frame_id == "base"
        target = {"Rotation": 0.5, "Pitch": 0.3, "Elbow": 0.9, "Wrist_Pitch": 1.2, "Wrist_Roll": -0.4, "Jaw": 1.0}
        command.publish(M.JointState(name=list(target), position=np.array(list(target.values()))))
        wait_until(lambda: all(abs(joints()[n] - v) < 0.03 for n, v in target.items()), 30, interval=0.1,
                   what=f"the arm at {target}")
        # A command naming a joint the arm does not have is rejected whole; the arm holds.
        command.publish(M.JointState(name=["Rotation", "shoulder_pan"], position=np.array([-0.5, 0.0])))
        time.sleep(1.0)
        assert joints()["Rotation"] == pytest.approx(0.5, abs=0.03)
        # A target beyond the joint limit is clipped to it (Jaw: -0.17..1.75 rad).
        command.publish(M.JointState(name=["Jaw"], position=np.array([3.0])))
        wait_until(lambda: abs(joints()["Jaw"] - 1.75) < 0.03, 30, interval=0.1, what="the jaw at its limit")
        image = wait_until(front.latest, 30, what="a front camera frame")
        assert (image.width, image.height, image.encoding, image.header.frame_id) == (160, 120, "rgb8", "front_camera")
        rgb = image.to_numpy()
        orange = (rgb[:, :, 0] > 200) & (rgb[:, :, 1] > 90) & (rgb[:, :, 1] < 180) & (rgb[:, :, 2] < 60)
        assert orange.sum() > 50  # the oranges are in view
        jpeg = wait_until(wrist.latest, 30, what="a wrist camera frame")
        from PIL import Image

        frame = Image.open(io.BytesIO(jpeg.data.tobytes()))
        assert frame.format == "JPEG" and frame.size == (160, 120) and jpeg.header.frame_id == "wrist_camera"
        status = system.rpc.call("tree")  # still supervised and running
        assert status
    finally:
        for s in (states, front, wrist, command):
            s.close()
        assert system.stop() == 0
    assert "rejected command #1 on /isaac_joint_command: arm has no joint 'shoulder_pan'" in system.output()


def test_a_scripted_pick_puts_an_orange_in_the_bowl():
    """The table-top physics is good enough to manipulate: reach, pinch, lift, carry, drop."""
    import math

    from emos.actors.sim import SimClock
    from emos.actors.sim.arm.tabletop import BOWL_CENTER, BOWL_RADIUS, TABLE_HEIGHT, orange_positions, tabletop_world

    world = tabletop_world(clock=SimClock(mode="lockstep"))
    try:
        arm, c = world.arm, world.client
        down = c.getQuaternionFromEuler([0, math.pi, 0])

        def move(xyz, jaw: float, seconds: float = 1.5) -> None:
            q = c.calculateInverseKinematics(arm.body_id, arm.link_index["gripper"], xyz, down,
                                             maxNumIterations=300, residualThreshold=1e-4)
            names = [n for n in arm.names if n != "Jaw"]
            arm.command(names + ["Jaw"], list(q[:5]) + [jaw])
            world.run_for(seconds)

        others = orange_positions(world)[1:].copy()
        x, y, z = orange_positions(world)[0]
        # The jaw is on the gripper's +x, which points to world -x when the gripper points down:
        # stand 2 cm to +x so the orange sits between the fixed finger and the open jaw.
        move([x + 0.02, y, z + 0.15], jaw=1.2)
        move([x + 0.02, y, z + 0.065], jaw=1.2)
        move([x + 0.02, y, z + 0.065], jaw=-0.17, seconds=1.0)
        assert arm.held == world.oranges[0]
        move([x + 0.02, y, z + 0.16], jaw=-0.17)
        assert orange_positions(world)[0][2] > z + 0.06  # lifted
        move([BOWL_CENTER[0] + 0.02, BOWL_CENTER[1], TABLE_HEIGHT + 0.16], jaw=-0.17)
        move([BOWL_CENTER[0] + 0.02, BOWL_CENTER[1], TABLE_HEIGHT + 0.16], jaw=1.2)
        move([BOWL_CENTER[0] + 0.02, BOWL_CENTER[1], TABLE_HEIGHT + 0.22], jaw=1.2)
        assert arm.held is None
        ox, oy, oz = orange_positions(world)[0]
        assert math.hypot(ox - BOWL_CENTER[0], oy - BOWL_CENTER[1]) < BOWL_RADIUS - 0.03  # inside the bowl
        assert oz < TABLE_HEIGHT + 0.05  # resting on its bottom, not on the rim or the fingers
        assert np.allclose(orange_positions(world)[1:], others, atol=0.01)  # the other oranges stayed put
    finally:
        world.close()
