"""Agent components fail at definition time with errors that name the thing; the small pure
parts they are built from (worker backlog, fixed inputs, conversions, tracker, wakeword)."""
from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from emos import Event, FixedInput, Topic
from emos import msgs as M
from emos.actors.agents import (
    LLM,
    MLLM,
    VLM,
    ChromaClient,
    ChromaDB,
    LLMConfig,
    MapEncoding,
    MapLayer,
    OllamaClient,
    OllamaModel,
    Route,
    SemanticRouter,
    SpeechToTextConfig,
    Vision,
    VisionConfig,
)
from emos.actors.agents.components.convert import OutputConversionError, to_message
from emos.actors.agents.logic.tracking import CentroidTracker
from emos.core.offload import StepWorker

pytestmark = pytest.mark.unit

CLIENT = OllamaClient(OllamaModel(name="llama", checkpoint="llama3.2:3b"))
Q = Topic(name="q", msg_type="String")
A = Topic(name="a", msg_type="String")
IMG = Topic(name="image_raw", msg_type="Image")


def test_wrong_topic_types_and_missing_parts_fail_at_definition():
    with pytest.raises(TypeError, match="input '/image_raw' carries sensor_msgs/msg/Image"):
        LLM(inputs=[IMG], outputs=[A], model_client=CLIENT, trigger=IMG, component_name="llm")
    with pytest.raises(TypeError, match="output '/scan' carries sensor_msgs/msg/LaserScan"):
        LLM(inputs=[Q], outputs=[Topic(name="scan", msg_type="LaserScan")], model_client=CLIENT, trigger=Q, component_name="llm")
    with pytest.raises(ValueError, match="needs an image input"):
        VLM(inputs=[Q], outputs=[A], model_client=CLIENT, trigger=Q, component_name="vlm")
    with pytest.raises(ValueError, match="needs a model_client"):
        LLM(inputs=[Q], outputs=[A], model_client=None, trigger=Q, component_name="llm")
    with pytest.raises(ValueError, match="model_client or config.enable_local_classifier"):
        Vision(inputs=[IMG], outputs=[Topic(name="d", msg_type="Detections")], trigger=IMG, component_name="vision")
    with pytest.raises(ValueError, match="enable_rag=True needs a collection_name"):
        LLMConfig(enable_rag=True)
    with pytest.raises(ValueError, match="enable_wakeword=True needs enable_vad=True"):
        SpeechToTextConfig(enable_wakeword=True)
    with pytest.raises(ValueError, match="must be in \\[0.0, 1.0\\]"):
        VisionConfig(threshold=1.5)
    route = Route(routes_to=Q, samples=["hello"])
    with pytest.raises(ValueError, match="exactly one of db_client"):
        SemanticRouter(inputs=[A], routes=[route], component_name="router")
    with pytest.raises(TypeError, match="position must be an Odometry"):
        MapEncoding(layers=[MapLayer(subscribes_to=Q)], position=Q, map_topic=Topic(name="map", msg_type="OccupancyGrid"),
                    db_client=ChromaClient(db=ChromaDB()), component_name="map")


def test_templates_preprocessors_and_fixed_inputs_are_checked_when_set():
    llm = LLM(inputs=[Q], outputs=[A], model_client=CLIENT, trigger=Q, component_name="llm")
    with pytest.raises(ValueError, match=r"uses \['text0'\], but only \['q'\] are available"):
        llm.set_component_prompt("Answer: {{ text0 }}")
    with pytest.raises(ValueError, match="'/nope' is not an output"):
        llm.add_publisher_preprocessor(Topic(name="nope", msg_type="String"), str.upper)
    with pytest.raises(TypeError, match="must accept exactly one positional argument"):
        llm.add_publisher_preprocessor(A, lambda a, b: a)
    fixed = FixedInput(name="question", msg_type="String", fixed="What room is this?")
    assert fixed.message == M.String(data="What room is this?")
    with pytest.raises(ValueError, match="fixed must be a non-empty value"):
        FixedInput(name="question", msg_type="String", fixed="  ")
    with pytest.raises(ValueError, match="cannot be a trigger"):
        MLLM(inputs=[fixed, IMG], outputs=[A], model_client=CLIENT, trigger=fixed, component_name="intro")
    intro = MLLM(inputs=[fixed, IMG], outputs=[A], model_client=CLIENT, trigger=15.0, component_name="intro")
    assert intro.in_topics == [IMG] and intro.input_topics == [fixed, IMG]  # no subscription to a fixed input
    assert intro.config.loop_rate == pytest.approx(1 / 15)


def test_output_conversion_names_topic_type_and_value():
    pose = to_message(M.PoseStamped, np.array([1.0, 2.0]), "goal_point")
    assert (pose.pose.position.x, pose.pose.position.y, pose.pose.position.z) == (1.0, 2.0, 0.0)
    assert to_message(M.StreamingString, "hi").done is True
    with pytest.raises(OutputConversionError, match="output 'goal_point' \\(PoseStamped\\) needs 2 or 3 finite numbers"):
        to_message(M.PoseStamped, [1.0, float("nan")], "goal_point")
    with pytest.raises(OutputConversionError, match="output 'a' \\(String\\) needs text, got ndarray"):
        to_message(M.String, np.zeros(3), "a")


def test_step_worker_keeps_the_latest_or_a_bounded_queue_and_survives_errors():
    gate = threading.Event()
    done: list[int] = []
    errors: list[BaseException] = []
    latest = StepWorker("cam", "latest", on_error=errors.append)
    latest.start()
    latest.submit(gate.wait)  # busy until the gate opens
    time.sleep(0.05)
    for i in range(5):
        latest.submit(lambda i=i: done.append(i))
    gate.set()
    assert latest.wait_idle(5)
    assert done == [4] and latest.dropped == 4  # only the newest frame waited
    latest.submit(lambda: 1 / 0)
    assert latest.wait_idle(5)
    latest.submit(lambda: done.append(99))
    assert latest.wait_idle(5) and done[-1] == 99 and isinstance(errors[0], ZeroDivisionError)
    assert latest.stop(2)
    queue = StepWorker("llm", "queue", max_pending=2)
    assert not queue.submit(lambda: None)  # not started: refused, not silently kept
    queue.start()
    gate.clear()
    queue.submit(gate.wait)
    time.sleep(0.05)
    for i in range(4):
        queue.submit(lambda i=i: done.append(10 + i))
    gate.set()
    assert queue.wait_idle(5) and done[-2:] == [12, 13] and queue.dropped == 2
    assert queue.stop(2) and not queue.running


def test_centroid_tracker_keeps_ids_and_measures_velocity():
    tracker = CentroidTracker(max_distance=30, max_age=1.0)
    first = tracker.update(np.array([[0, 0, 10, 10], [100, 100, 110, 110]]), ["cup", "cup"], stamp=0.0)
    second = tracker.update(np.array([[105, 100, 115, 110], [5, 0, 15, 10]]), ["cup", "cup"], stamp=0.5)
    assert list(second.ids) == [first.ids[1], first.ids[0]]
    assert np.allclose(second.velocities, [[10, 0], [10, 0]])
    third = tracker.update(np.array([[500, 500, 510, 510]]), ["cup"], stamp=3.0)  # old tracks expired
    assert third.ids[0] not in set(first.ids)


def test_wakeword_is_matched_on_the_transcript_and_arms_the_next_utterance():
    from emos.actors.agents import SpeechToText
    from emos.actors.agents.clients import RoboMLWSClient
    from emos.actors.agents.models import Whisper

    stt = SpeechToText(inputs=[Topic(name="audio0", msg_type="Audio")], outputs=[Q], component_name="stt",
                       model_client=RoboMLWSClient(Whisper(name="whisper")),
                       config=SpeechToTextConfig(enable_vad=True, enable_wakeword=True))
    assert stt._after_wakeword("Hey Jarvis, what time is it") == "what time is it"
    assert stt._after_wakeword("what time is it") == ""  # not addressed to us
    assert stt._after_wakeword("hey jarvis") == ""  # the wakeword alone arms...
    assert stt._after_wakeword("bring me the cup") == "bring me the cup"  # ...the next utterance
    assert stt._after_wakeword("and the plate") == ""


def test_vla_mapping_limits_and_command_types(tmp_path):
    from emos.actors.agents import VLA, LeRobotClient, LeRobotPolicy, VLAConfig
    from emos.actors.agents.components.vla_interface import joint_limits_from_urdf

    info = str(__import__("pathlib").Path(__file__).parent / "fixtures" / "lerobot_info.json")
    joints = {"shoulder_pan.pos": "Rotation", "shoulder_lift.pos": "Pitch", "elbow_flex.pos": "Elbow",
              "wrist_flex.pos": "Wrist_Pitch", "wrist_roll.pos": "Wrist_Roll", "gripper.pos": "Jaw"}
    cams = {"front": Topic(name="camera", msg_type="Image"), "wrist": Topic(name="wrist_camera", msg_type="Image")}
    state = Topic(name="joint_states", msg_type="JointState")
    policy = LeRobotPolicy(name="p", checkpoint="x", dataset_info_file=info)
    urdf = tmp_path / "arm.urdf"
    urdf.write_text('<robot name="r"><joint name="Jaw" type="revolute"><limit lower="0" upper="0.5"/></joint></robot>')
    assert joint_limits_from_urdf(urdf) == {"Jaw": (0.0, 0.5)}
    with pytest.raises(ValueError, match=r"the URDF has no limits for joints \['Rotation'"):
        VLA(inputs=[state, *cams.values()], outputs=[Topic(name="cmd", msg_type="JointState")],
            model_client=LeRobotClient(policy), component_name="vla",
            config=VLAConfig(joint_names_map=joints, camera_inputs_map=cams, robot_urdf_file=str(urdf)))
    # The dataset info is read at configure (issue 33 D8), and the maps are checked against it there.
    short = VLA(inputs=[state, *cams.values()], outputs=[Topic(name="cmd", msg_type="JointState")],
                model_client=LeRobotClient(LeRobotPolicy(name="p", checkpoint="x", dataset_info_file=info)), component_name="vla",
                config=VLAConfig(joint_names_map=joints, camera_inputs_map={"front": cams["front"]}))
    with pytest.raises(ValueError, match=r"camera_inputs_map lacks the policy's cameras \['wrist'\]"):
        short.custom_on_configure()
    outputs = [Topic(name="cmd", msg_type="JointState"), Topic(name="traj", msg_type="JointTrajectory"),
               Topic(name="jog", msg_type="JointJog")]
    vla = VLA(inputs=[state, *cams.values()], outputs=outputs, model_client=LeRobotClient(policy), component_name="vla",
              config=VLAConfig(joint_names_map=joints, camera_inputs_map=cams, joint_limits={"Jaw": (0.0, 0.5)}))
    names, values = list(joints.values()), np.array([0.1, 0.2, 0.3, 0.4, 0.5, 0.5])
    assert vla._cap("Jaw", 0.9) == 0.5 and vla._cap("Rotation", 9.0) == 9.0
    assert list(vla._command(M.JointState, names, values).position) == list(values)
    assert list(vla._command(M.JointTrajectory, names, values).points[0].positions) == list(values)
    assert vla._command(M.JointJog, names, values).joint_names == names
    with pytest.raises(TypeError, match=r"set_termination_trigger\('event'\) needs stop_event=Event"):
        vla.set_termination_trigger("event")
    with pytest.raises(ValueError, match="'keyboard' needs an interactive terminal"):
        vla.set_termination_trigger("keyboard")
    with pytest.raises(ValueError, match="stop_event is only used with mode='event'"):
        vla.set_termination_trigger("timesteps", stop_event=Event(state))
    verdict = Topic(name="verdict", msg_type="String")
    success = Event(verdict.msg.data.contains("YES"))
    vla.set_termination_trigger("event", stop_event=success, max_timesteps=400)
    assert vla.termination == {"mode": "event", "max_timesteps": 400}
    [(event, [action])] = vla._own_events_actions
    assert event is success and action.component == "vla" and action.method_name == "stop_on_event"
    from supervisor.orchestration import Orchestration  # the launcher hands the stop event to the Monitor
    assert (success, [action]) in Orchestration().all_events([vla])
    vla.set_termination_trigger("timesteps", max_timesteps=5)
    assert vla._own_events_actions == [] and vla.termination == {"mode": "timesteps", "max_timesteps": 5}
