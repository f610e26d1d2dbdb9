"""A component fills a camera frame in shared memory with ``self.loan`` (the loaned-message API of
ROS 2 and iceoryx2), and what arrives is that frame, whole."""
from __future__ import annotations

import numpy as np
import pytest

from emos import BaseComponent, Topic
from emos.msgs import Image
from emos.testing import ComponentHarness

pytestmark = pytest.mark.unit


class Camera(BaseComponent):
    """Each step writes frame number k (every pixel k % 251) straight into the ring slot."""

    def custom_on_activate(self) -> None:
        self.k = 0

    def _execution_step(self, **kwargs) -> None:
        self.k += 1
        with self.loan("/camera/rgb", Image, shape=(480, 640, 3), encoding="rgb8") as msg:
            msg.data[...] = self.k % 251
        self.health_status.set_healthy()


class Failing(Camera):
    def _execution_step(self, **kwargs) -> None:
        with pytest.raises(RuntimeError), self.loan("/camera/rgb", Image, shape=(4, 4, 3)) as msg:
            msg.data[...] = 1
            raise RuntimeError("the driver lost the frame")
        self.health_status.set_healthy()


def _camera(cls: type) -> BaseComponent:
    cam = cls(component_name="camera", outputs=[Topic(name="/camera/rgb", msg_type="Image")])
    cam.config.loop_rate = 10.0
    return cam


def test_a_component_publishes_a_loaned_frame_that_arrives_whole():
    with ComponentHarness(_camera(Camera)) as h:
        h.advance(0.3)
        frames = h.outputs("/camera/rgb")
    assert len(frames) >= 2
    for i, frame in enumerate(frames, start=1):
        assert (frame.height, frame.width, frame.encoding, frame.step) == (480, 640, "rgb8", 640 * 3)
        pixels = np.asarray(frame.data).reshape(-1)
        assert pixels.size == 480 * 640 * 3 and np.all(pixels == i % 251)


def test_a_loan_given_up_by_an_exception_publishes_nothing():
    with ComponentHarness(_camera(Failing)) as h:
        h.advance(0.3)
        assert h.outputs("/camera/rgb") == []
