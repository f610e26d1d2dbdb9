"""Planning tasks over RoboML: the task travels in the request, the local server grounds a
description with its detector on the image it was sent, and structured answers come back as
text the VLM's task parser reads."""
from __future__ import annotations

import base64

import cv2
import numpy as np
import pytest

from emos.actors.agents.clients import roboml_codec
from emos.actors.agents.errors import MalformedResponseError
from emos.actors.agents.local.grounding import box_centres, ground, named_class
from emos.actors.agents.local.vision import Detection
from emos.actors.agents.logic.vlm_tasks import GroundingResult, parse_vlm_output
from emos.actors.agents.server.backends import LocalModels
from emos.actors.agents.server.roboml_nodes import NodeError, RoboMLNodes
from emos.actors.agents.types import ChatMessage, ChatRequest, ImageData
from tests.agents.test_agents_local_models import _figure

pytestmark = pytest.mark.unit


def _png(image: np.ndarray) -> str:
    ok, data = cv2.imencode(".png", image[:, :, ::-1])
    assert ok
    return base64.b64encode(data.tobytes()).decode()


def test_the_description_names_a_detector_class():
    assert named_class("the tall man by the door") == "person"
    assert named_class("Person") == "person"
    assert named_class("her face") == "face"
    assert named_class("the red cup") is None
    found = [Detection("face", 0.9, (1, 1, 5, 5)), Detection("person", 0.6, (0, 0, 10, 30)),
             Detection("person", 0.8, (20, 0, 30, 30))]
    assert ground(found, "a person") == [[20, 0, 30, 30], [0, 0, 10, 30]]  # best first
    assert ground(found, "the cup") == []
    assert box_centres([[20, 0, 30, 30]]) == [[25.0, 15.0]]


def test_local_server_grounds_a_person_in_the_image_it_was_sent():
    nodes = RoboMLNodes(LocalModels())
    nodes.add_node("robobrain", "RoboBrain2")
    nodes.initialize("robobrain", {"checkpoint": "BAAI/RoboBrain2.0-7B"})
    figure = _figure()
    query = [{"role": "user", "content": "the person"}]
    (box,) = nodes.inference("robobrain", {"query": query, "images": [_png(figure)], "task": "grounding"})["output"]
    x1, y1, x2, y2 = box
    assert x1 < 150 < x2 and y1 < 120 < y2  # around the figure drawn at (150, 40..240)
    (point,) = nodes.inference("robobrain", {"query": query, "images": [_png(figure)], "task": "pointing"})["output"]
    assert point == [round((x1 + x2) / 2, 1), round((y1 + y2) / 2, 1)]
    empty = np.full_like(figure, 200)
    assert nodes.inference("robobrain", {"query": query, "images": [_png(empty)], "task": "grounding"})["output"] == []
    # No image, an unknown task, a stream: clear errors.
    with pytest.raises(NodeError, match="needs an image"):
        nodes.inference("robobrain", {"query": query, "task": "grounding"})
    with pytest.raises(NodeError, match="task 'trajectory'.*planning tasks") as err:
        nodes.inference("robobrain", {"query": query, "images": [_png(figure)], "task": "trajectory"})
    assert err.value.status == 501
    with pytest.raises(NodeError, match="cannot stream"):
        nodes.inference("robobrain", {"query": query, "images": [_png(figure)], "task": "grounding", "stream": True})


def test_roboml_codec_sends_the_task_and_reads_structured_answers():
    request = ChatRequest(messages=[ChatMessage(role="user", content="the person",
                                                images=[ImageData.from_array(np.zeros((8, 8, 3), np.uint8))])],
                          task="grounding")
    payload = roboml_codec.build_payload(request, "chat")
    assert payload["task"] == "grounding" and len(payload["images"]) == 1
    assert "task" not in roboml_codec.build_payload(ChatRequest(messages=[ChatMessage(role="user", content="hi")]), "chat")
    response = roboml_codec.parse_output({"output": [[10, 20, 30, 60]]}, "chat", "BAAI/RoboBrain2.0-7B", {})
    result = parse_vlm_output("grounding", response.message.content)
    assert isinstance(result, GroundingResult) and result.boxes.tolist() == [[10, 20, 30, 60]]
    import msgpack

    packed = roboml_codec.parse_value(msgpack.packb([[1, 2, 3, 4]]), "chat", "m", {})  # the WebSocket's frame
    assert packed.message.content == "[[1, 2, 3, 4]]"
    with pytest.raises(MalformedResponseError):
        roboml_codec.parse_value(b"\xc1", "chat", "m", {})
