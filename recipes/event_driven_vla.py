"""Event-driven VLA (planning-and-manipulation recipe): a VLA "player" picks oranges while a VLM
"referee" looks at the front camera every 10 s; an Event on the referee's verdict ends the
player's goal as a success the moment the answer contains YES.

    emos serve models --lerobot-port 8080 --script recipes/models/responder.yaml &
    emos run recipes/event_driven_vla.py
    emos action send_goal vla_player vision_language_action '{"task": "pick up the oranges and place them in the bowl"}'

Ported from the spec by changing imports, with its errata fixed (the joint and camera maps
defined, ``event_task_success`` as the stop event, ``trigger=10.0`` for the referee). The
``Simulator``'s table-top world stands in for Isaac Sim. Offline, the policy is the
deterministic stand-in of ``emos serve models`` (it holds the arm's pose) and the referee's
model is its scripted responder, which does not look at the image: it answers YES (see
recipes/models/responder.yaml); a real VLM (qwen2.5vl:7b on Ollama) judges the picture.
"""
import os
from pathlib import Path

from emos import Event, FixedInput, Launcher, Topic
from emos.actors.agents import VLA, VLM, LeRobotClient, LeRobotPolicy, OllamaClient, OllamaModel, VLAConfig
from emos.actors.sim import Simulator, SimulatorConfig
from emos.actors.sim.arm import ARM_URDF

HERE = Path(__file__).resolve().parent
MODELS_PORT = int(os.environ.get("EMOS_MODELS_PORT", "8000"))  # `emos serve models` (Ollama API)
POLICY_PORT = int(os.environ.get("EMOS_POLICY_PORT", "8080"))

# --- Define Topics (the simulator's names; the spec uses Isaac's /isaac_joint_states etc.) ---
state = Topic(name="joint_states", msg_type="JointState")
camera1 = Topic(name="camera", msg_type="Image")
camera2 = Topic(name="wrist_camera", msg_type="Image")
joints_action = Topic(name="joint_command", msg_type="JointState")
referee_verdict = Topic(name="/referee/verdict", msg_type="String")

# --- Setup The Player (VLA) ---
policy = LeRobotPolicy(
    name="my_policy",
    policy_type="smolvla",
    checkpoint="aleph-ra/smolvla_finetune_pick_orange_20000",
    # Offline: the dataset's info.json ships with the recipes (the spec fetches it from the Hub).
    dataset_info_file=str(HERE / "models" / "so101_pick_orange_info.json"),
)
vla_client = LeRobotClient(model=policy, port=POLICY_PORT)

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
    observation_sending_rate=5,
    action_sending_rate=5,
    joint_names_map=joints_map,
    camera_inputs_map=camera_map,
    robot_urdf_file=os.environ.get("EMOS_ARM_URDF") or str(ARM_URDF),  # the simulated arm's URDF
)

player = VLA(
    inputs=[state, camera1, camera2],
    outputs=[joints_action],
    model_client=vla_client,
    config=config,
    component_name="vla_player",
)

# --- Setup The Referee (VLM) ---
qwen_vl = OllamaModel(name="qwen_vl", checkpoint="qwen2.5vl:7b")
qwen_client = OllamaClient(model=qwen_vl, port=MODELS_PORT)

# A static prompt for the VLM
question = FixedInput(
    name="prompt",
    msg_type="String",
    fixed="Look at the image. Are all the orange in the bowl? Answer only with YES or NO.",
)

referee = VLM(
    inputs=[question, camera1],
    outputs=[referee_verdict],
    model_client=qwen_client,
    trigger=10.0,  # errata: ask every 10 s (the spec's complete code triggers on every frame)
    component_name="vlm_referee",
)

# --- Define the Logic (Event) ---
# Fires when the referee's answer contains YES
event_task_success = Event(referee_verdict.msg.data.contains("YES"))

# Link the event to the VLA's stop mechanism
player.set_termination_trigger(
    mode="event",
    stop_event=event_task_success,
    max_timesteps=400,  # Failsafe
)

# --- The simulated arm (instead of Isaac Sim) ---
# Cameras at 3 Hz: a CPU render costs ~55 ms per frame here; the player re-sends the latest frame.
sim = Simulator("sim", config=SimulatorConfig(world="tabletop", camera_rate=3.0))
sim.inputs(joint_command=joints_action)
sim.outputs(joint_states=state, camera=camera1, wrist_camera=camera2)

# --- Launch ---
launcher = Launcher()
launcher.add_pkg(components=[sim], package_name="simulation", multiprocessing=True)
launcher.add_pkg(components=[player, referee])
launcher.bringup()
