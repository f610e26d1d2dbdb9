"""VLA against the local LeRobot policy server (hold-position policy) and a small simulated arm
that publishes its joint states (SO-101 joint names) and follows the joint commands."""
from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np
import pytest

from emos import msgs as M
from tests.agents.components_helpers import AGENT_HEADER, Probe
from tests.runtime.helpers import SystemUnderTest, wait_until

pytestmark = pytest.mark.process

FIXTURES = Path(__file__).parent / "fixtures"
JOINTS = ["Rotation", "Pitch", "Elbow", "Wrist_Pitch", "Wrist_Roll", "Jaw"]
URDF = """<robot name="so101_like">
""" + "".join(f"""  <joint name="{j}" type="revolute"><limit lower="-1.5" upper="{0.5 if j == 'Jaw' else 1.5}" effort="1" velocity="1"/></joint>
""" for j in JOINTS) + "</robot>\n"


class Arm:
    """Publishes joint states (shuffled name order, as drivers do) and moves to each command."""

    def __init__(self, probe: Probe) -> None:
        self.probe = probe
        self.position = {"Rotation": 0.1, "Pitch": -0.2, "Elbow": 0.3, "Wrist_Pitch": -0.4, "Wrist_Roll": 0.5, "Jaw": 0.9}
        self.commands: list[M.JointState] = []
        self._stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        order = ["Jaw", "Elbow", "Rotation", "Wrist_Roll", "Pitch", "Wrist_Pitch"]
        frame = np.zeros((48, 64, 3), np.uint8)
        while not self._stop.is_set():
            for cmd in self.probe.sub("/joint_command", "JointState").take():
                self.commands.append(cmd)
                self.position.update(dict(zip(cmd.name, cmd.position)))
            self.probe.pub("/joint_states", M.JointState(name=order, position=np.array([self.position[j] for j in order])))
            self.probe.pub("/camera", M.Image.from_numpy(frame))
            self.probe.pub("/wrist_camera", M.Image.from_numpy(frame))
            time.sleep(0.05)

    def stop(self) -> None:
        self._stop.set()
        self.thread.join(2)


def test_vla_maps_joints_caps_to_the_urdf_and_stops_after_max_timesteps(tmp_path, model_server):
    (tmp_path / "arm.urdf").write_text(URDF)
    system = SystemUnderTest(tmp_path, AGENT_HEADER + f"""
from emos.actors.agents import VLA, VLAConfig, LeRobotClient, LeRobotPolicy
state = Topic(name="joint_states", msg_type="JointState")
camera1 = Topic(name="camera", msg_type="Image")
camera2 = Topic(name="wrist_camera", msg_type="Image")
# A deep ring: the test's arm thread may stall for a second on a loaded machine and must not lose commands.
joints_action = Topic(name="joint_command", msg_type="JointState", qos_profile={{"queue_size": 100}})
policy = LeRobotPolicy(name="my_policy", policy_type="smolvla", checkpoint="hold-position",
                       dataset_info_file={str(FIXTURES / "lerobot_info.json")!r}, actions_per_chunk=5)
client = LeRobotClient(model=policy, port={model_server.lerobot_port})
joints_map = {{"shoulder_pan.pos": "Rotation", "shoulder_lift.pos": "Pitch", "elbow_flex.pos": "Elbow",
              "wrist_flex.pos": "Wrist_Pitch", "wrist_roll.pos": "Wrist_Roll", "gripper.pos": "Jaw"}}
config = VLAConfig(observation_sending_rate=5, action_sending_rate=10, joint_names_map=joints_map,
                   camera_inputs_map={{"front": camera1, "wrist": camera2}}, robot_urdf_file={str(tmp_path / "arm.urdf")!r})
vla = VLA(inputs=[state, camera1, camera2], outputs=[joints_action], model_client=client, config=config,
          component_name="vla_with_smolvla")
vla.set_termination_trigger("timesteps", max_timesteps=12)
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[vla])
launcher.bringup()
""", duration=120).wait_up(components=["vla_with_smolvla"], timeout=60)
    probe = Probe(system)
    arm = Arm(probe)
    try:
        arm.thread.start()
        from emos.actors.agents.components.vla_interface import (
            VisionLanguageActionFeedback,
            VisionLanguageActionGoal,
            VisionLanguageActionResult,
        )
        from emos.core.services import ActionClient

        client = ActionClient("vla_with_smolvla/vision_language_action", VisionLanguageActionGoal,
                              VisionLanguageActionFeedback, VisionLanguageActionResult, ctx=system.ctx)
        feedback: list[int] = []
        result = client.send_goal(VisionLanguageActionGoal(task="pick up the oranges and place them in the bowl"),
                                  feedback_callback=lambda f: feedback.append(f.timestep), timeout=60)
        assert result.success and result.timesteps == 12
        assert feedback == list(range(12))
        wait_until(lambda: len(arm.commands) >= 12, 10, what="12 joint commands")
        first = arm.commands[0]
        assert first.name == JOINTS  # the policy's order mapped back to the robot's joint names
        # Held positions, except the jaw: 0.9 is past the URDF's upper limit of 0.5.
        assert np.allclose(first.position, [0.1, -0.2, 0.3, -0.4, 0.5, 0.5])
        time.sleep(0.5)
        count = len(arm.commands)
        time.sleep(0.5)
        assert len(arm.commands) == count  # the goal ended: no more commands
    finally:
        arm.stop()
        probe.close()
        assert system.stop() == 0


def test_vla_event_termination_stops_the_running_goal_and_keeps_the_failsafe(tmp_path, model_server):
    """Termination by event: with no firing the goal runs into max_timesteps (a failure); a
    firing during a goal ends it (a success); a firing from before a goal does not end it."""
    system = SystemUnderTest(tmp_path, AGENT_HEADER + f"""
from emos import Event
from emos.actors.agents import VLA, VLAConfig, LeRobotClient, LeRobotPolicy
state = Topic(name="joint_states", msg_type="JointState")
camera1 = Topic(name="camera", msg_type="Image")
camera2 = Topic(name="wrist_camera", msg_type="Image")
verdict = Topic(name="verdict", msg_type="String")
policy = LeRobotPolicy(name="my_policy", policy_type="smolvla", checkpoint="hold-position",
                       dataset_info_file={str(FIXTURES / "lerobot_info.json")!r}, actions_per_chunk=5)
client = LeRobotClient(model=policy, port={model_server.lerobot_port})
joints_map = {{"shoulder_pan.pos": "Rotation", "shoulder_lift.pos": "Pitch", "elbow_flex.pos": "Elbow",
              "wrist_flex.pos": "Wrist_Pitch", "wrist_roll.pos": "Wrist_Roll", "gripper.pos": "Jaw"}}
config = VLAConfig(observation_sending_rate=10, action_sending_rate=10, joint_names_map=joints_map,
                   camera_inputs_map={{"front": camera1, "wrist": camera2}})
vla = VLA(inputs=[state, camera1, camera2], outputs=[Topic(name="joint_command", msg_type="JointState")],
          model_client=client, config=config, component_name="vla")
vla.set_termination_trigger("event", stop_event=Event(verdict.msg.data.contains("YES")), max_timesteps=30)
launcher = Launcher()
launcher.add_pkg(components=[vla])
launcher.bringup()
""", duration=120).wait_up(components=["vla"], timeout=60)
    probe = Probe(system)
    arm = Arm(probe)
    try:
        arm.thread.start()
        from emos.actors.agents.components.vla_interface import (
            VisionLanguageActionFeedback,
            VisionLanguageActionGoal,
            VisionLanguageActionResult,
        )
        from emos.core.services import ActionClient

        client = ActionClient("vla/vision_language_action", VisionLanguageActionGoal,
                              VisionLanguageActionFeedback, VisionLanguageActionResult, ctx=system.ctx)
        goal = VisionLanguageActionGoal(task="pick up the oranges")
        probe.pub("/verdict", M.String(data="NO"))  # does not match: no firing
        result = client.send_goal(goal, goal_id="g1", timeout=60)
        assert not result.success and result.timesteps == 30
        assert result.message == "max_timesteps (30) reached before the stop event fired"
        probe.pub("/verdict", M.String(data="YES"))  # fires with no goal running
        time.sleep(1.0)
        outcome: list = []
        feedback: list[int] = []
        thread = threading.Thread(target=lambda: outcome.append(client.send_goal(
            goal, goal_id="g2", feedback_callback=lambda f: feedback.append(f.timestep), timeout=60)))
        thread.start()
        wait_until(lambda: len(feedback) >= 5, 30, what="five timesteps of the second goal")  # the old firing did not end it
        probe.pub("/verdict", M.String(data="YES, they are"))
        thread.join(30)
        assert outcome and outcome[0].success and outcome[0].message.startswith("stop event after")
        assert 5 <= outcome[0].timesteps < 30
    finally:
        arm.stop()
        probe.close()
        assert system.stop() == 0
