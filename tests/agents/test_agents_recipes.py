"""The intelligence recipes under recipes/, run with ``emos run`` against the real local model
server (recipes/models/responder.yaml as the stand-in chat model), fed and read on topics."""
from __future__ import annotations

import io
import time
import wave
from pathlib import Path

import numpy as np
import pytest

from emos import msgs as M
from tests.agents.components_helpers import Probe
from tests.agents.fixtures.server_process import start_server
from tests.agents.test_agents_local_models import _figure
from tests.runtime.helpers import SystemUnderTest, wait_until

REPO = Path(__file__).resolve().parents[2]
RECIPES = REPO / "recipes"


@pytest.fixture(scope="module")
def recipe_server():
    import httpx

    server = start_server(script=str(RECIPES / "models" / "responder.yaml"))
    httpx.post(f"http://127.0.0.1:{server.port}/v1/embeddings", json={"model": "all-minilm-l6-v2", "input": ["warm"]},
               timeout=180).raise_for_status()
    yield server
    server.stop()


def _run(tmp_path, recipe: str, server, components: list[str]) -> tuple[SystemUnderTest, Probe]:
    env = {"EMOS_MODELS_PORT": str(server.port), "EMOS_MODELS_RESP_PORT": str(server.resp_port), "HOME": str(tmp_path)}
    system = SystemUnderTest(tmp_path, (RECIPES / recipe).read_text(), duration=240, env=env)
    system.wait_up(components=components, timeout=90)
    return system, Probe(system)


def _chroma(tmp_path, server):
    from emos.actors.agents import ChromaClient, ChromaDB

    client = ChromaClient(db=ChromaDB(path=str(tmp_path / ".cache" / "emos" / "chroma"), embeddings="ollama",
                                      checkpoint="all-minilm", ollama_port=server.port))
    client.initialize()
    return client


def _seed_map(tmp_path, server) -> None:
    """The semantic map a previous run left: a kitchen and a door at known places."""
    client = _chroma(tmp_path, server)
    client.upsert("map", ["kitchen", "door"], ids=["a", "b"], metadatas=[
        {"coordinates": [1.5, 2.5, 0.0], "layer_name": "introspection_answer", "timestamp": 1.0, "temporal_change": False},
        {"coordinates": [-3.0, 0.5, 0.0], "layer_name": "detections", "timestamp": 1.0, "temporal_change": True}])
    client.deinitialize()


def _speech_chunks(text: str) -> list[np.ndarray]:
    from emos.actors.agents.local.audio import read_wav, resample
    from emos.actors.agents.local.tts import EspeakTTS

    samples, rate = read_wav(EspeakTTS().synthesize(text))
    pcm = np.concatenate([np.zeros(8000, np.float32), resample(samples, rate, 16000), np.zeros(16000, np.float32)])
    ints = (pcm * 32767).astype("<i2")
    return [ints[i:i + 512].view(np.uint8) for i in range(0, len(ints), 512)]


def _position(msg) -> list[float]:
    p = msg.pose.position
    return [round(p.x, 3), round(p.y, 3), round(p.z, 3)]


def test_conversational_agent_hears_looks_and_speaks(tmp_path, recipe_server):
    system, probe = _run(tmp_path, "conversational_agent.py", recipe_server, ["speech_to_text", "vqa", "text_to_speech"])
    try:
        for topic, kind in (("/text0", "String"), ("/text1", "String"), ("/audio_out", "Audio")):
            probe.sub(topic, kind)
        probe.pub("/image_raw", M.Image.from_numpy(_figure()))
        for chunk in _speech_chunks("what is the weather like"):
            probe.pub("/audio0", M.Audio(data=chunk))
            time.sleep(0.02)
        assert probe.collect("/text0", "String", timeout=90)[0].data == "what is the weather like"
        answer = probe.collect("/text1", "String", timeout=60)[0].data
        assert answer == "Looking at the image: what is the weather like"
        audio = probe.collect("/audio_out", "Audio", timeout=60)[0].data.tobytes()
        with wave.open(io.BytesIO(audio)) as w:
            assert w.getnframes() / w.getframerate() > 1.0  # the whole sentence was spoken
    finally:
        probe.close()
        assert system.stop() == 0


def test_prompt_engineering_puts_detections_in_the_prompt(tmp_path, recipe_server):
    system, probe = _run(tmp_path, "prompt_engineering.py", recipe_server, ["detection_component", "mllm_component"])
    try:
        probe.sub("/detections", "Detections"), probe.sub("/text1", "String")
        probe.pub("/image_raw", M.Image.from_numpy(_figure()))
        assert probe.collect("/detections", "Detections", timeout=60)[0].labels == ["person"]
        probe.pub("/text0", M.String(data="what is the person doing?"))
        assert probe.collect("/text1", "String", timeout=60)[0].data == "I see person. You asked: what is the person doing?"
    finally:
        probe.close()
        assert system.stop() == 0


def test_tool_calling_turns_the_map_into_a_goal(tmp_path, recipe_server):
    _seed_map(tmp_path, recipe_server)
    system, probe = _run(tmp_path, "tool_calling.py", recipe_server, ["go_to_x"])
    try:
        probe.sub("/goal_point", "PoseStamped")
        probe.pub("/goto_in", M.String(data="Go to the kitchen"))
        assert _position(probe.collect("/goal_point", "PoseStamped", timeout=60)[0]) == [1.5, 2.5, 0.0]
        probe.pub("/goto_in", M.String(data="Go to the door"))
        assert _position(probe.collect("/goal_point", "PoseStamped", timeout=60)[0]) == [-3.0, 0.5, 0.0]
    finally:
        probe.close()
        assert system.stop() == 0


def test_semantic_routing_sends_questions_to_the_right_component(tmp_path, recipe_server):
    _seed_map(tmp_path, recipe_server)
    system, probe = _run(tmp_path, "semantic_routing.py", recipe_server, ["generic_llm", "go_to_x", "router"])
    try:
        probe.sub("/goal_point", "PoseStamped"), probe.sub("/text_out_llm", "String")
        probe.pub("/question", M.String(data="Please go to the kitchen"))
        assert _position(probe.collect("/goal_point", "PoseStamped", timeout=90)[0]) == [1.5, 2.5, 0.0]
        probe.pub("/question", M.String(data="What is the capital of Spain?"))
        assert probe.collect("/text_out_llm", "String", timeout=60)[0].data == "You said: What is the capital of Spain?"
        assert probe.drain("/goal_point", "PoseStamped") == []
    finally:
        probe.close()
        assert system.stop() == 0


def test_semantic_map_stores_detections_and_the_room(tmp_path, recipe_server):
    system, probe = _run(tmp_path, "semantic_map.py", recipe_server, ["detection_component", "introspector", "map_encoding"])
    grid = M.OccupancyGrid(info=M.MapMetaData(resolution=0.5, width=20, height=20), data=np.zeros(400, np.int8))
    odom = M.Odometry()
    odom.pose.pose.position.x, odom.pose.pose.position.y = 1.2, 0.4
    try:
        probe.pub("/map", grid)
        probe.pub("/odom", odom)
        probe.pub("/image_raw", M.Image.from_numpy(_figure()))
        client = _chroma(tmp_path, recipe_server)
        # The introspector asks every 15 s and the map is written every 15 s.
        wait_until(lambda: {r.document for r in client.metadata_query("map")} >= {"person", "kitchen"}, 75,
                   interval=1.0, what="the person and the kitchen in the map")
        entries = {r.document: r.metadata for r in client.metadata_query("map")}
        assert entries["kitchen"]["coordinates"][:2] == [0.75, 0.75]  # 1.5 m cells
        assert entries["person"]["coordinates"][:2] == [1.25, 0.25]  # 0.5 m cells
        client.deinitialize()
    finally:
        probe.close()
        assert system.stop() == 0


@pytest.mark.parametrize("recipe", ["complete_agent.py", "multiprocessing_agent.py"])
def test_complete_agent_routes_sees_and_navigates(tmp_path, recipe_server, recipe):
    _seed_map(tmp_path, recipe_server)
    components = ["visual_q_and_a", "general_q_and_a", "go_to_x", "introspector", "map_encoder", "router",
                  "speech_to_text", "text_to_speech", "object_detection"]
    system, probe = _run(tmp_path, recipe, recipe_server, components)
    try:
        probe.sub("/goal_point", "PoseStamped"), probe.sub("/answer", "String"), probe.sub("/detections", "Detections")
        probe.pub("/image_raw", M.Image.from_numpy(_figure()))
        assert probe.collect("/detections", "Detections", timeout=90)[0].labels == ["person"]
        probe.pub("/question", M.String(data="Go to the kitchen"))
        assert _position(probe.collect("/goal_point", "PoseStamped", timeout=90)[0]) == [1.5, 2.5, 0.0]
        probe.pub("/question", M.String(data="Do you see any people?"))
        assert probe.collect("/answer", "String", timeout=60)[0].data == "I see person. You asked: Do you see any people?"
        if recipe == "multiprocessing_agent.py":
            pids = {c: system.pid(c) for c in components}
            assert len(set(pids.values())) == len(components) and system.proc.pid not in pids.values()
    finally:
        probe.close()
        assert system.stop() == 0


def test_goto_navigation_reads_the_goal_from_the_map(tmp_path, recipe_server):
    _seed_map(tmp_path, recipe_server)
    system, probe = _run(tmp_path, "goto_navigation.py", recipe_server, ["go_to_x"])
    try:
        probe.sub("/goal_point", "PoseStamped")
        probe.pub("/goto_in", M.String(data="Go to the kitchen"))
        assert _position(probe.collect("/goal_point", "PoseStamped", timeout=60)[0]) == [1.5, 2.5, 0.0]
    finally:
        probe.close()
        assert system.stop() == 0


def test_vla_manipulation_commands_the_arm_until_canceled(tmp_path, recipe_server):
    import threading

    from emos.actors.agents.components.vla_interface import (VisionLanguageActionFeedback, VisionLanguageActionGoal,
                                                             VisionLanguageActionResult)
    from emos.core.services import ActionCanceled, ActionClient
    from tests.agents.test_agents_component_vla import JOINTS, Arm

    import shutil

    shutil.copytree(RECIPES / "models", tmp_path / "models")  # the recipe reads files beside itself
    env = {"EMOS_POLICY_PORT": str(recipe_server.lerobot_port)}
    system = SystemUnderTest(tmp_path, (RECIPES / "vla_manipulation.py").read_text(), duration=120, env=env)
    system.wait_up(components=["vla_with_smolvla"], timeout=90)
    probe = Probe(system)
    arm = Arm(probe)
    outcome: list = []
    try:
        arm.thread.start()
        client = ActionClient("vla_with_smolvla/vision_language_action", VisionLanguageActionGoal,
                              VisionLanguageActionFeedback, VisionLanguageActionResult, ctx=system.ctx)

        def run_goal() -> None:
            try:
                outcome.append(client.send_goal(VisionLanguageActionGoal(task="pick up the oranges"), goal_id="g1", timeout=60))
            except ActionCanceled as exc:
                outcome.append(exc)

        thread = threading.Thread(target=run_goal)
        thread.start()
        wait_until(lambda: len(arm.commands) >= 3, 30, what="three joint commands at 3 Hz")
        assert arm.commands[0].name == JOINTS
        assert np.allclose(arm.commands[0].position, [0.1, -0.2, 0.3, -0.4, 0.5, 0.9])  # held (no URDF here)
        assert client.cancel("g1")
        thread.join(10)
        assert outcome and isinstance(outcome[0], ActionCanceled)
    finally:
        arm.stop()
        probe.close()
        assert system.stop() == 0
