"""``VisionConfig(enable_visualization=True)`` (both vision-tracking pages of the spec pass it):
the frame with its detections drawn on it, published as an Image topic instead of the
original's pop-up window (robots are usually headless)."""
import numpy as np
import pytest

from emos import Topic
from emos.actors.agents import Vision, VisionConfig
from emos.actors.agents.components.vision_viz import annotate, label_colour, tile
from emos.actors.agents.types import Detection2D

pytestmark = pytest.mark.unit

IMAGE = Topic(name="/image_raw/compressed", msg_type="CompressedImage")
DETS = Topic(name="detections", msg_type="Detections")


def _vision(**config):
    return Vision(inputs=[IMAGE], outputs=[DETS], trigger=IMAGE, component_name="detection_component",
                  config=VisionConfig(enable_local_classifier=True, **config))


def test_the_spec_lines_build_and_declare_the_visualization_output():
    # vision-tracking-rgb.md: VisionConfig(threshold=0.5, enable_visualization=True)
    vision = _vision(threshold=0.5, enable_visualization=True)
    topic = vision.visualization_topic
    assert topic is not None and topic.name == "/detection_component/visualization" and topic.msg_type.__name__ == "Image"
    assert topic in vision.out_topics  # declared with the outputs: the run creates its ring
    assert VisionConfig().enable_visualization is False
    plain = _vision()
    assert plain.visualization_topic is None and [t.name for t in plain.out_topics] == ["/detections"]


def test_bad_values_and_a_clashing_output_are_clear_errors():
    with pytest.raises(TypeError, match="enable_visualization"):
        VisionConfig(enable_visualization="yes")
    clash = Topic(name="/detection_component/visualization", msg_type="Detections")
    with pytest.raises(ValueError, match="already one of its outputs"):
        Vision(inputs=[IMAGE], outputs=[clash], component_name="detection_component",
               config=VisionConfig(enable_local_classifier=True, enable_visualization=True))


def test_annotate_draws_each_box_in_its_label_colour_and_leaves_the_frame_alone():
    frame = np.full((120, 160, 3), 30, np.uint8)
    result = Detection2D(boxes=[[20, 40, 80, 100], [np.nan, 0, 10, 10], [150, 110, 400, 900]],
                         labels=["person", "ghost", "cup"], scores=[0.9, 0.8, 0.7])
    out = annotate(frame, result)
    assert out.shape == frame.shape and out.dtype == np.uint8
    assert (frame == 30).all()  # a copy is drawn on
    person = np.array(label_colour("person"), np.uint8)
    assert (out[70, 20] == person).all() and (out[70, 80] == person).all()  # left and right edges
    assert (out[70, 50] == 30).all()  # the inside of the box is the frame's
    cup = np.array(label_colour("cup"), np.uint8)
    assert (out[119, 155] == cup).all()  # a box beyond the picture is clipped to it
    assert label_colour("person") == label_colour("person") != label_colour("cup")
    # the non-finite box is skipped, not drawn at (0, 0) and not an error
    assert (annotate(frame, Detection2D(boxes=[[np.nan, 0, 10, 10]], labels=["ghost"], scores=[0.8])) == 30).all()
    # no detections: the frame as it is
    assert (annotate(frame, Detection2D(boxes=np.zeros((0, 4)))) == frame).all()


def test_several_cameras_are_tiled_at_the_first_ones_height():
    a = np.zeros((100, 50, 3), np.uint8)
    b = np.full((50, 40, 3), 255, np.uint8)
    out = tile([a, b])
    assert out.shape == (100, 130, 3)
    assert (out[:, :50] == 0).all() and (out[:, 50:] == 255).all()
    assert tile([a]) is a
