"""Which image travels with a Vision component's detections (consumers such as the Controller's
vision followers read the image size and, for RGBD, the depth from it)."""
import numpy as np
import pytest

from emos import Topic
from emos.actors.agents import Vision, VisionConfig
from emos.actors.agents.components.vision import _attached_image
from emos.msgs import CompressedImage, Header, Image
from emos.msgs.control import RGBD

pytestmark = pytest.mark.unit


def test_rgbd_input_is_allowed_and_its_depth_travels_with_the_detections():
    Vision(inputs=[Topic(name="/camera/rgbd", msg_type="RGBD")], outputs=[Topic(name="detections", msg_type="Detections")],
           config=VisionConfig(enable_local_classifier=True), component_name="vision")
    rgb = np.zeros((4, 6, 3), np.uint8)
    depth = Image.from_numpy(np.full((4, 6), 2.0, np.float32), encoding="32FC1")
    msg = RGBD(rgb=Image.from_numpy(rgb), depth=depth)
    assert _attached_image(msg, rgb, Header(), include_image=False) is depth


def test_include_image_attaches_compressed_frames_as_the_decoded_rgb8_pixels():
    rgb = np.arange(4 * 6 * 3, dtype=np.uint8).reshape(4, 6, 3)
    compressed = CompressedImage(format="jpeg", data=np.zeros(3, np.uint8))
    image = _attached_image(compressed, rgb, Header(frame_id="cam"), include_image=True)
    assert (image.width, image.height, image.encoding) == (6, 4, "rgb8")
    np.testing.assert_array_equal(image.to_numpy(), rgb)
    assert _attached_image(compressed, rgb, Header(), include_image=False) is None
    raw = Image.from_numpy(rgb)
    assert _attached_image(raw, rgb, Header(), include_image=True) is raw
