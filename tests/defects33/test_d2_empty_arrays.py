"""Issue 33 D2: an empty list is the empty array of any array field with a free (-1) dimension
(``Detections.boxes`` of shape (-1, 4) from ``[]`` is (0, 4)), at the message level and
through ``emos topic pub``; fixed sizes and wrong ranks are still refused."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from emos import msgs as M
from emos.msgs.fields import FieldTypeError
from tests.runtime.helpers import HANG_S, SystemUnderTest, wait_until


@pytest.mark.unit
def test_empty_list_is_an_empty_array_of_the_fields_shape():
    d = M.Detections(labels=[], scores=[], boxes=[])
    assert d.boxes.shape == (0, 4) and d.boxes.dtype == np.float64 and d.scores.shape == (0,)
    d.boxes = np.zeros(0)  # on assignment too, and from an empty numpy array
    assert d.boxes.shape == (0, 4)
    t = M.Trackings(ids=[], labels=[], boxes=[], centroids=[], estimated_velocities=[])
    assert t.boxes.shape == (0, 4) and t.centroids.shape == (0, 2) and t.estimated_velocities.shape == (0, 2)
    assert M.TwistArray(linear_velocities=[], angular_velocities=[]).linear_velocities.shape == (0, 3)
    # through the codec and from built-in data (what the CLI and the UI send) alike
    from emos.msgs import codec

    assert codec.unpack(M.Detections, codec.pack(d)).boxes.shape == (0, 4)
    assert codec.from_builtin(M.Detections, {"labels": [], "scores": [], "boxes": []}).boxes.shape == (0, 4)


@pytest.mark.unit
@pytest.mark.parametrize("bad", [[1.0, 2.0, 3.0], [[1.0, 2.0, 3.0]], np.zeros((0, 3)), [[[]]]])
def test_wrong_shapes_are_still_refused(bad):
    with pytest.raises(FieldTypeError, match=r"Detections.boxes expects an array of float64 with shape \(-1, 4\)"):
        M.Detections(labels=[], scores=[], boxes=bad)


@pytest.mark.unit
def test_a_fixed_size_array_does_not_take_an_empty_list():
    with pytest.raises(FieldTypeError, match=r"CameraInfo.k expects an array of float64 with shape \(9,\)"):
        M.CameraInfo(k=[])


@pytest.mark.process
def test_emos_topic_pub_publishes_empty_detections(tmp_path):
    system = SystemUnderTest(tmp_path, """
from pathlib import Path

class Sink(BaseComponent):
    def _execution_step(self):
        msg = self.get_input("/detections")
        if msg is not None:
            Path("got.txt").write_text(f"{len(msg.labels)} {msg.boxes.shape} {msg.scores.shape}")
        self.health_status.set_healthy()

c = Sink(component_name="sink", inputs=[Topic(name="/detections", msg_type="Detections")])
c.config.loop_rate = 20.0
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[c])
launcher.bringup()
""").wait_up(components=["sink"])
    try:
        pub = subprocess.run([sys.executable, "-m", "emos", "topic", "pub", "--run", system.run_dir.name, "--rate", "20", "--count", "20",
                              "/detections", "Detections", '{"labels": [], "scores": [], "boxes": []}'],
                             capture_output=True, text=True, timeout=HANG_S, cwd=tmp_path)
        assert pub.returncode == 0 and "Traceback" not in pub.stderr, pub.stdout + pub.stderr
        got = tmp_path / "got.txt"
        assert wait_until(lambda: got.exists() and got.read_text(), what="the empty detections at the subscriber") == "0 (0, 4) (0,)"
    finally:
        system.stop()
