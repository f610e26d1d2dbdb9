"""VLA manipulation (planning-and-manipulation recipe): a LeRobot policy drives a 6-DOF
SO-101-like arm from its joint states and two cameras.

    emos serve models --lerobot-port 8080 &      # stand-in policy server (holds the arm's pose)
    emos run recipes/vla_manipulation.py
    # then, as on the spec's page (its `ros2 action send_goal /vla_with_smolvla/vision_language_action ...`):
    emos action send_goal vla_with_smolvla vision_language_action '{"task": "pick up the oranges and place them in the bowl"}'

The ``Simulator``'s table-top world (pybullet: the arm, three oranges, a bowl) stands in for
the spec's Isaac Sim scene: it publishes ``joint_states``, ``camera`` and ``wrist_camera`` and
follows ``joint_command``. On a real arm, drop the simulator: its driver publishes and
follows the same topics (set ``EMOS_ARM_URDF`` to the arm's URDF for the joint caps).
Offline, the policy server is the deterministic stand-in of ``emos serve models`` and the
dataset description ships beside this recipe.
"""
import os
from pathlib import Path

from emos import Launcher, Topic
from emos.actors.agents import VLA, LeRobotClient, LeRobotPolicy, VLAConfig
from emos.actors.sim import Simulator, SimulatorConfig
from emos.actors.sim.arm import ARM_URDF

HERE = Path(__file__).resolve().parent
POLICY_PORT = int(os.environ.get("EMOS_POLICY_PORT", "8080"))

# --- Define Topics (the simulator's names; the spec uses Isaac's /isaac_joint_states etc.) ---
state = Topic(name="joint_states", msg_type="JointState")
camera1 = Topic(name="camera", msg_type="Image")
camera2 = Topic(name="wrist_camera", msg_type="Image")
joints_action = Topic(name="joint_command", msg_type="JointState")

# --- Setup Policy (The Brain) ---
policy = LeRobotPolicy(
    name="my_policy",
    policy_type="smolvla",
    checkpoint="aleph-ra/smolvla_finetune_pick_orange_20000",
    # Offline: the dataset's info.json ships with the recipes (the spec fetches it from the Hub).
    dataset_info_file=str(HERE / "models" / "so101_pick_orange_info.json"),
)
client = LeRobotClient(model=policy, port=POLICY_PORT)

# --- Configure Mapping (The Nervous System) ---
joints_map = {
    "shoulder_pan.pos": "Rotation",
    "shoulder_lift.pos": "Pitch",
    "elbow_flex.pos": "Elbow",
    "wrist_flex.pos": "Wrist_Pitch",
    "wrist_roll.pos": "Wrist_Roll",
    "gripper.pos": "Jaw",
}
camera_map = {"front": camera1, "wrist": camera2}

config = VLAConfig(
    observation_sending_rate=3,  # Hz: How often we infer
    action_sending_rate=3,  # Hz: How often we publish commands
    joint_names_map=joints_map,
    camera_inputs_map=camera_map,
    # URDF for safety capping and joint limit verification (the simulated arm's own by default)
    robot_urdf_file=os.environ.get("EMOS_ARM_URDF") or str(ARM_URDF),
)

vla = VLA(
    inputs=[state, camera1, camera2],
    outputs=[joints_action],
    model_client=client,
    config=config,
    component_name="vla_with_smolvla",
)
vla.set_termination_trigger("timesteps", max_timesteps=50)

# --- The simulated arm (instead of Isaac Sim / the real robot) ---
# Cameras at the policy's observation rate: a CPU render costs ~55 ms per frame here.
sim = Simulator("sim", config=SimulatorConfig(world="tabletop", camera_rate=3.0))
sim.inputs(joint_command=joints_action)
sim.outputs(joint_states=state, camera=camera1, wrist_camera=camera2)

launcher = Launcher()
launcher.add_pkg(components=[sim], package_name="simulation", multiprocessing=True)
launcher.add_pkg(components=[vla], package_name="manipulation", multiprocessing=True)
launcher.bringup()
