"""Request/response types: images and MIME types, tool-call decoding, history copies, errors."""
from __future__ import annotations

import base64
import pickle

import cv2
import numpy as np
import pytest

from emos.actors.agents.errors import (
    MalformedResponseError,
    ModelClientError,
    ModelConnectionError,
    ModelServerError,
    ModelTimeoutError,
)
from emos.actors.agents.types import (
    ChatChunk,
    ChatMessage,
    ChatRequest,
    Detection2D,
    ImageData,
    ToolCall,
    ToolSpec,
    decode_tool_arguments,
    encode_png,
    sniff_image_mime,
)

pytestmark = pytest.mark.unit


@pytest.mark.parametrize("shape", [(5, 7), (5, 7, 3), (5, 7, 4), (5, 7, 1)])
def test_png_encoding_round_trips_through_opencv(shape):
    rng = np.random.default_rng(1)
    image = rng.integers(0, 256, shape, dtype=np.uint8)
    decoded = cv2.imdecode(np.frombuffer(encode_png(image), np.uint8), cv2.IMREAD_UNCHANGED)
    expected = image[:, :, 0] if shape == (5, 7, 1) else image
    if expected.ndim == 3:  # OpenCV decodes to BGR(A)
        decoded = decoded[:, :, [2, 1, 0, 3][: expected.shape[2]]]
    assert np.array_equal(decoded, expected)


def test_png_encoding_rejects_wrong_shapes():
    with pytest.raises(ValueError, match="HxW"):
        encode_png(np.zeros((2, 2, 2), np.uint8))


def test_mime_types_are_sniffed_from_magic_bytes():
    jpeg = cv2.imencode(".jpg", np.zeros((4, 4, 3), np.uint8))[1].tobytes()
    webp = cv2.imencode(".webp", np.zeros((4, 4, 3), np.uint8))[1].tobytes()
    assert sniff_image_mime(encode_png(np.zeros((2, 2), np.uint8))) == "image/png"
    assert sniff_image_mime(jpeg) == "image/jpeg"
    assert sniff_image_mime(webp) == "image/webp"
    assert ImageData.coerce(jpeg).to_data_url().startswith("data:image/jpeg;base64,")
    with pytest.raises(ValueError, match="PNG, JPEG, WebP or GIF"):
        ImageData.coerce(b"not an image")


def test_images_are_coerced_from_arrays_bytes_and_base64():
    array = np.full((3, 3, 3), 200, np.uint8)
    from_array = ImageData.coerce(array)
    assert from_array.mime_type == "image/png"
    assert ImageData.coerce(from_array.to_base64()) == from_array
    assert ImageData.coerce(from_array.to_data_url()) == from_array
    assert base64.b64decode(from_array.to_base64()) == from_array.data
    with pytest.raises(TypeError, match="ImageData, bytes, numpy array"):
        ImageData.coerce(3.14)


def test_history_copy_drops_images_but_keeps_the_text():
    message = ChatMessage(role="user", content="what is this?", images=[np.zeros((2, 2, 3), np.uint8)])
    assert len(message.images) == 1
    kept = message.text_only()
    assert kept.images == [] and kept.content == "what is this?" and len(message.images) == 1


def test_tool_arguments_are_always_dicts():
    assert decode_tool_arguments('{"place": "kitchen"}') == {"place": "kitchen"}
    assert decode_tool_arguments({"place": "kitchen"}) == {"place": "kitchen"}
    assert decode_tool_arguments("") == {} and decode_tool_arguments(None) == {}
    for bad in ('{"place": ', "[1, 2]", 42):
        with pytest.raises(MalformedResponseError, match="tool-call arguments"):
            decode_tool_arguments(bad, client="c", url="http://x")
    call = ToolCall(id=7, name="go_to")
    assert call.id == "7" and call.arguments == {}
    with pytest.raises(TypeError):
        ToolCall(id="1", name="go_to", arguments='{"a": 1}')


def test_message_and_request_validation():
    with pytest.raises(ValueError, match="role"):
        ChatMessage(role="robot", content="hi")
    with pytest.raises(ValueError, match="at least one message"):
        ChatRequest(messages=[])
    with pytest.raises(ValueError, match="temperature"):
        ChatRequest(messages=[ChatMessage("user", "x")], temperature=3.0)
    with pytest.raises(ValueError, match="type 'object'"):
        ToolSpec(name="t", parameters={"type": "string"})
    request = ChatRequest(messages=[{"role": "user", "content": "x"}],
                          tools=[{"type": "function", "function": {"name": "go_to", "parameters": {"type": "object"}}}])
    assert isinstance(request.messages[0], ChatMessage) and request.tools[0].name == "go_to"


def test_null_chunk_content_becomes_empty_text():
    assert ChatChunk(content=None).content == ""


def test_detections_check_their_lengths():
    d = Detection2D(boxes=[[0, 0, 1, 1]], labels=["person"], scores=[0.9])
    assert d.boxes.shape == (1, 4)
    with pytest.raises(ValueError, match="differ in length"):
        Detection2D(boxes=[[0, 0, 1, 1]], labels=[], scores=[0.9])


@pytest.mark.parametrize(
    "error",
    [
        ModelConnectionError("cannot connect", client="OllamaClient", model="llama", url="http://h:1/api/chat"),
        ModelTimeoutError("slow", client="C", model="m", url="http://h"),
        ModelServerError("failed", status=503, body="overloaded" * 100, client="C", model="m", url="http://h"),
        MalformedResponseError("JSON", "<html>", client="C", model="m", url="http://h"),
    ],
)
def test_errors_name_client_model_and_url_and_survive_pickling(error):
    text = str(error)
    assert "client 'C" in text or "OllamaClient" in text
    assert "http://h" in text
    copy = pickle.loads(pickle.dumps(error))
    assert type(copy) is type(error) and str(copy) == text and isinstance(copy, ModelClientError)
    if isinstance(error, ModelServerError):
        assert copy.status == 503 and len(copy.body) <= ModelServerError.EXCERPT_CHARS
