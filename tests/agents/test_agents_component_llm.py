"""LLM / MLLM components as real processes against the real local model server."""
from __future__ import annotations

import socket

import numpy as np
import pytest

from emos import msgs as M
from tests.agents.components_helpers import AGENT_HEADER, Probe
from tests.agents.fixtures.server_process import start_server
from tests.runtime.helpers import SystemUnderTest, wait_until

pytestmark = pytest.mark.process


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _system(tmp_path, body: str, components: list[str]) -> tuple[SystemUnderTest, Probe]:
    system = SystemUnderTest(tmp_path, AGENT_HEADER + body, duration=120).wait_up(components=components, timeout=60)
    return system, Probe(system)


def test_llm_answers_with_templates_and_keeps_its_heartbeat(tmp_path, model_server):
    system, probe = _system(tmp_path, f"""
client = OllamaClient(OllamaModel(name="llama", checkpoint="llama3.2:3b"), port={model_server.port})
q = Topic(name="q", msg_type="String")
a = Topic(name="a", msg_type="String")
llm = LLM(inputs=[q], outputs=[a], model_client=client, trigger=q, component_name="brain")
llm.set_topic_prompt(q, template="{{{{ q }}}} please")
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[llm])
launcher.bringup()
""", ["brain"])
    try:
        out = probe.sub("/a", "String")
        pid = system.pid("brain")
        probe.pub("/q", M.String(data="hello"))
        probe.pub("/q", M.String(data="what colour is it"))
        got = probe.collect("/a", "String", 2)
        assert [m.data for m in got] == ["Hello! I am a robot.", "It is red."]
        probe.pub("/q", M.String(data="x y"))
        assert probe.collect("/a", "String")[0].data == "You said: x y please"  # the topic template applied
        assert probe.status("brain").status == M.ComponentStatus.STATUS_HEALTHY
        assert system.pid("brain") == pid
        out.take()
    finally:
        probe.close()
        assert system.stop() == 0


def test_llm_streams_in_break_character_pieces_into_string_and_streaming_topics(tmp_path, model_server):
    system, probe = _system(tmp_path, f"""
client = OllamaClient(OllamaModel(name="llama", checkpoint="llama3.2:3b"), port={model_server.port})
q = Topic(name="q", msg_type="String")
a = Topic(name="a", msg_type="String")
s = Topic(name="s", msg_type="StreamingString")
llm = LLM(inputs=[q], outputs=[a, s], model_client=client, trigger=q, component_name="streamer",
          config=LLMConfig(stream=True, break_character="."))
launcher = Launcher(multi_processing=False)
launcher.add_pkg(components=[llm])
launcher.bringup()
""", ["streamer"])
    try:
        probe.sub("/a", "String"), probe.sub("/s", "StreamingString")
        probe.pub("/q", M.String(data="one. two. three"))
        pieces = probe.collect("/a", "String", 3)
        assert [m.data for m in pieces] == ["You said: one.", "two.", "three"]
        streamed = probe.collect("/s", "StreamingString", 3)
        assert [(m.data, m.done) for m in streamed] == [("You said: one.", False), ("two.", False), ("three", True)]
    finally:
        probe.close()
        assert system.stop() == 0


def test_server_down_at_start_then_up_and_hot_swap_to_backup(tmp_path, model_server):
    port = _free_port()  # nothing listens here yet
    system, probe = _system(tmp_path, f"""
primary = OllamaClient(OllamaModel(name="primary", checkpoint="llama3.2:3b"), port={port})
backup = OllamaClient(OllamaModel(name="backup", checkpoint="llama3.2:3b"), port={model_server.port})
q = Topic(name="q", msg_type="String")
a = Topic(name="a", msg_type="String")
alone = LLM(inputs=[q], outputs=[Topic(name="alone_out", msg_type="String")], model_client=primary, trigger=q,
            component_name="alone")
brain = LLM(inputs=[q], outputs=[a], model_client=primary, trigger=q, component_name="brain")
brain.additional_model_clients = {{"local_backup_client": backup}}
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[alone, brain])
launcher.bringup()
""", ["alone", "brain"])
    server = None
    try:
        alone_pid = system.pid("alone")
        # Down at start: reported as a component failure, the process lives on.
        wait_until(lambda: probe.status("alone").status == M.ComponentStatus.STATUS_FAILURE_COMPONENT_LEVEL,
                   20, what="alone to report its unreachable model server")
        assert "ModelConnectionError" in probe.status("alone").message
        probe.sub("/a", "String"), probe.sub("/alone_out", "String")
        probe.pub("/q", M.String(data="hello"))
        # The component with a backup answers from it; the request that hit the dead primary is not lost.
        assert probe.collect("/a", "String")[0].data == "Hello! I am a robot."
        assert probe.drain("/alone_out", "String") == []
        # The primary server comes up: the lone component reconnects by itself and answers.
        server = start_server("--port", str(port))
        wait_until(lambda: probe.status("alone").status == M.ComponentStatus.STATUS_HEALTHY, 20,
                   what="alone to reconnect")
        probe.pub("/q", M.String(data="hello"))
        assert probe.collect("/alone_out", "String")[0].data == "Hello! I am a robot."
        assert system.pid("alone") == alone_pid
    finally:
        probe.close()
        if server is not None:
            server.stop()
        assert system.stop() == 0


def test_vlm_sees_the_image_and_rejects_a_broken_one(tmp_path, model_server):
    system, probe = _system(tmp_path, f"""
client = OllamaClient(OllamaModel(name="qwen_vl", checkpoint="qwen2.5vl:latest"), port={model_server.port})
q = Topic(name="q", msg_type="String")
image = Topic(name="image_raw", msg_type="Image")
a = Topic(name="a", msg_type="String")
vlm = VLM(inputs=[q, image], outputs=[a], model_client=client, trigger=q, component_name="vqa")
vlm.set_component_prompt("Answer about this image: {{{{ q }}}}")
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[vlm])
launcher.bringup()
""", ["vqa"])
    try:
        probe.sub("/a", "String")
        wait_until(lambda: probe.status("vqa").status == M.ComponentStatus.STATUS_HEALTHY, 10, what="vqa connected")
        probe.pub("/q", M.String(data="what colour is the ball"))
        # No image yet: a system-level failure naming the image topic, nothing published.
        wait_until(lambda: probe.status("vqa").status == M.ComponentStatus.STATUS_FAILURE_SYSTEM_LEVEL, 10, what="missing image")
        assert "/image_raw" in probe.status("vqa").src_topics
        frame = np.zeros((48, 64, 3), np.uint8)
        frame[..., 0] = 255
        bad = M.Image(height=48, width=64, encoding="rgb8", step=64 * 3, data=np.zeros(100, np.uint8))  # wrong size
        probe.pub("/image_raw", bad)
        probe.pub("/q", M.String(data="what colour is the ball"))
        wait_until(lambda: "needs 9216 bytes" in probe.status("vqa").message, 10, what="the wrong-shape image reported")
        assert probe.drain("/a", "String") == []
        probe.pub("/image_raw", M.Image.from_numpy(frame))
        probe.pub("/q", M.String(data="what colour is the ball"))
        assert probe.collect("/a", "String")[0].data == "It is red."
    finally:
        probe.close()
        assert system.stop() == 0


def test_vlm_grounding_task_publishes_typed_detections(tmp_path, model_server):
    system, probe = _system(tmp_path, f"""
client = OllamaClient(OllamaModel(name="qwen_vl", checkpoint="qwen2.5vl:latest"), port={model_server.port})
q = Topic(name="q", msg_type="String")
image = Topic(name="image_raw", msg_type="Image")
boxes = Topic(name="grounding", msg_type="Detections")
text = Topic(name="a", msg_type="String")
vlm = VLM(inputs=[q, image], outputs=[boxes, text], model_client=client, trigger=q, component_name="grounder",
          config=VLMConfig(task="grounding"))
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[vlm])
launcher.bringup()
""", ["grounder"])
    try:
        probe.sub("/grounding", "Detections"), probe.sub("/a", "String")
        probe.pub("/image_raw", M.Image.from_numpy(np.zeros((64, 64, 3), np.uint8)))
        probe.pub("/q", M.String(data="where is the cup in the image?"))
        (det,) = probe.collect("/grounding", "Detections")
        assert det.boxes.tolist() == [[12, 20, 40, 60]]
        assert probe.collect("/a", "String")[0].data == "The cup is at [12, 20, 40, 60]."
        probe.pub("/q", M.String(data="hello"))  # no box in the answer: an algorithm failure, nothing published
        wait_until(lambda: probe.status("grounder").status == M.ComponentStatus.STATUS_FAILURE_ALGORITHM_LEVEL, 15,
                   what="the unparsable answer reported")
        assert "grounding output" in probe.status("grounder").message
        assert probe.drain("/grounding", "Detections") == []
    finally:
        probe.close()
        assert system.stop() == 0


def test_vlm_grounds_on_an_rgbd_input_and_sends_the_depth_with_the_boxes(tmp_path, model_server):
    """RoboBrain 2.0 over RoboML with task="grounding": the server grounds the description in
    the colour image (its people detector); the Detections carry the RGBD frame's depth image."""
    from tests.agents.test_agents_local_models import _figure

    system, probe = _system(tmp_path, f"""
from emos.actors.agents import RoboBrain2, RoboMLHTTPClient
client = RoboMLHTTPClient(RoboBrain2(name="robobrain"), port={model_server.port})
q = Topic(name="q", msg_type="String")
rgbd = Topic(name="rgbd0", msg_type="RGBD")
boxes = Topic(name="grounding", msg_type="Detections")
vlm = VLM(inputs=[q, rgbd], outputs=[boxes], model_client=client, trigger=q, component_name="grounder",
          config=VLMConfig(task="grounding"))
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[vlm])
launcher.bringup()
""", ["grounder"])
    try:
        probe.sub("/grounding", "Detections")
        figure = _figure()  # 300 x 400, a person drawn around x = 150
        header = M.Header(stamp=M.Time(sec=12, nanosec=5), frame_id="camera/depth")
        depth = M.Image.from_numpy(np.full(figure.shape[:2], 2.5, np.float32), encoding="32FC1", header=header)
        info = M.CameraInfo.from_intrinsics(300, 400, 300.0, 300.0, 149.5, 199.5, header=header)
        probe.pub("/rgbd0", M.RGBD(header=header, rgb=M.Image.from_numpy(figure), depth=depth,
                                   rgb_camera_info=info, depth_camera_info=info))
        probe.pub("/q", M.String(data="person"))
        (det,) = probe.collect("/grounding", "Detections")
        x1, y1, x2, y2 = det.boxes[0]
        assert x1 < 150 < x2 and y1 < 120 < y2
        assert det.image is not None and det.image.encoding == "32FC1" and det.image.header.frame_id == "camera/depth"
        assert det.image.to_numpy().shape == figure.shape[:2] and float(det.image.to_numpy()[0, 0]) == 2.5
        assert (det.header.stamp.sec, det.header.frame_id) == (12, "camera/depth")  # about that frame
        probe.pub("/q", M.String(data="the red cup"))  # nothing the detector knows: no box, an algorithm failure
        wait_until(lambda: probe.status("grounder").status == M.ComponentStatus.STATUS_FAILURE_ALGORITHM_LEVEL, 15,
                   what="the empty grounding reported")
        assert "grounding output: expected at least one box" in probe.status("grounder").message
        assert probe.drain("/grounding", "Detections") == []
    finally:
        probe.close()
        assert system.stop() == 0


def test_chat_history_reaches_the_model_and_the_reset_phrase_clears_it(tmp_path, model_server):
    system, probe = _system(tmp_path, f"""
client = OllamaClient(OllamaModel(name="llama", checkpoint="llama3.2:3b"), port={model_server.port})
q = Topic(name="q", msg_type="String")
a = Topic(name="a", msg_type="String")
llm = LLM(inputs=[q], outputs=[a], model_client=client, trigger=q, component_name="chatty",
          config=LLMConfig(chat_history=True, history_size=4))
launcher = Launcher(multi_processing=False)
launcher.add_pkg(components=[llm])
launcher.bringup()
""", ["chatty"])
    try:
        probe.sub("/a", "String")
        replies = []
        for _ in range(4):
            probe.pub("/q", M.String(data="count turns"))
            replies.append(probe.collect("/a", "String")[0].data)
        # history_size=4 keeps two exchanges: the third question is the first to see the window full.
        assert replies == ["turn 1", "turn 2", "turn 3", "turn 3"]
        probe.pub("/q", M.String(data="Chat reset."))
        assert probe.drain("/a", "String") == []  # the reset phrase is not a question
        probe.pub("/q", M.String(data="count turns"))
        assert probe.collect("/a", "String")[0].data == "turn 1"
    finally:
        probe.close()
        assert system.stop() == 0
