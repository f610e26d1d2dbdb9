"""A running Vision component with ``enable_visualization=True`` publishes each frame with its
detections drawn on it, on ``<component>/visualization``, next to the detections themselves."""
import numpy as np
import pytest

from emos import msgs as M
from emos.actors.agents.components.vision_viz import label_colour
from tests.agents.components_helpers import AGENT_HEADER, Probe
from tests.agents.test_agents_local_models import _figure
from tests.runtime.helpers import SystemUnderTest, kill_leftover_systems, wait_until

pytestmark = pytest.mark.process


@pytest.fixture(autouse=True)
def _no_system_outlives_its_test():
    yield
    kill_leftover_systems()


def test_the_annotated_frame_is_published_with_the_detections(tmp_path):
    system = SystemUnderTest(tmp_path, AGENT_HEADER + """
from emos.actors.agents import Vision, VisionConfig
image = Topic(name="image_raw", msg_type="Image")
dets = Topic(name="detections", msg_type="Detections")
vision = Vision(inputs=[image], outputs=[dets], trigger=image, component_name="vision",
                config=VisionConfig(threshold=0.5, enable_local_classifier=True, enable_visualization=True))
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[vision])
launcher.bringup()
""", duration=120).wait_up(components=["vision"], timeout=60)
    probe = Probe(system)
    try:
        probe.sub("/detections", "Detections"), probe.sub("/vision/visualization", "Image")
        wait_until(lambda: probe.status("vision").status == M.ComponentStatus.STATUS_HEALTHY, 30, what="vision ready")
        figure = _figure()
        probe.pub("/image_raw", M.Image.from_numpy(figure, header=M.Header(frame_id="cam")))
        (det,) = probe.collect("/detections", "Detections")
        (picture,) = probe.collect("/vision/visualization", "Image")
        assert det.labels == ["person"]
        assert (picture.width, picture.height, picture.encoding) == (figure.shape[1], figure.shape[0], "rgb8")
        assert picture.header.frame_id == "cam"  # stamped like the frame it shows
        pixels = picture.to_numpy()
        x1, y1, x2, y2 = (int(v) for v in np.clip(det.boxes[0], 0, [299, 399, 299, 399]))
        colour = np.array(label_colour("person"), np.uint8)
        # the box's left edge, half-way down, is drawn in the person colour; the input was grey/ink
        assert (pixels[(y1 + y2) // 2, x1] == colour).all()
        assert not (figure == colour).all(axis=2).any()
    finally:
        probe.close()
        assert system.stop() == 0
