"""`emos record` and `emos play` against real systems: the sensor demo recorded, replayed into a checker."""
from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
import zlib
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mcap")
pytest.importorskip("rosbags")

from emos.interop.mcap_bag import BagInfo, read_bag
from tests.runtime.helpers import REPO, SystemUnderTest

pytestmark = pytest.mark.process

CHECKER_RECIPE = """
import json, zlib
from emos.msgs import Image, LaserScan

class Checker(BaseComponent):
    def custom_on_configure(self):
        self.seen = {"camera": [], "lidar": []}

    def _execution_step(self, msg=None, topic=None):
        now = time.time()
        if isinstance(msg, Image):
            name, payload = "camera", msg.data
        elif isinstance(msg, LaserScan):
            name, payload = "lidar", msg.ranges
        else:
            return
        seq, crc = msg.header.frame_id.split(":")
        ok = zlib.crc32(np.ascontiguousarray(payload).data) & 0xFFFFFFFF == int(crc)
        self.seen[name].append([int(seq), ok, msg.header.stamp.to_sec(), now])
        self.health_status.set_healthy()

    def custom_on_deactivate(self):
        with open(os.environ["CHECKER_OUT"], "w") as f:
            json.dump(self.seen, f)

rgb = Topic(name="camera/rgb", msg_type="Image")
scan = Topic(name="scan", msg_type="LaserScan")
checker = Checker(component_name="checker", inputs=[rgb, scan], trigger=[rgb, scan])
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[checker])
launcher.bringup()
"""


def emos(*args: str, **kw) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "emos", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kw)


def finish(proc: subprocess.Popen, timeout: float = 60.0) -> str:
    out, err = proc.communicate(timeout=timeout)
    assert proc.returncode == 0, f"exit {proc.returncode}\n{out}\n{err}"
    return out


def crc_ok(msg) -> bool:
    payload = msg.data if hasattr(msg, "encoding") else msg.ranges
    return zlib.crc32(np.ascontiguousarray(payload).data) & 0xFFFFFFFF == int(msg.header.frame_id.split(":")[1])


def test_record_sensor_demo_then_replay_into_a_checker(tmp_path: Path):
    demo_dir = tmp_path / "demo"
    demo_dir.mkdir()
    demo = SystemUnderTest(demo_dir, (REPO / "recipes" / "sensor_demo.py").read_text()).wait_up(components=["camera", "lidar", "checker"])
    run = demo.ctx.run_id
    bag, killed_bag = tmp_path / "demo.mcap", tmp_path / "killed.mcap"

    # Two recorders at once: one stopped by SIGTERM (must close the file properly), one
    # SIGKILLed (must leave a file readable up to its last complete chunk).
    rec = emos("record", "--run", run, "-o", str(bag))
    killed = emos("record", "--run", run, "-o", str(killed_bag), "/camera/rgb", "--chunk-size", "3000000", "-q")
    # One left running: it must end by itself, file complete, when the system stops.
    until_end = emos("record", "--run", run, "-o", str(tmp_path / "until_end.mcap"), "/scan", "-q")
    time.sleep(1.0)
    # A topic that appears while recording is recorded too.
    late = emos("topic", "pub", "--run", run, "late", "std_msgs/String", '{"data": "late"}', "--rate", "20", "--count", "40")
    finish(late)
    time.sleep(1.0)
    killed.send_signal(signal.SIGKILL)
    killed.wait(10)
    rec.send_signal(signal.SIGTERM)
    out = finish(rec)
    assert "stopped by SIGTERM" in out
    demo.stop()
    assert "the system stopped" in finish(until_end, timeout=30)
    end_info = BagInfo()
    assert sum(1 for _ in read_bag(tmp_path / "until_end.mcap", info=end_info)) > 0
    assert not end_info.truncated

    info = BagInfo()
    messages = list(read_bag(bag, info=info))
    assert not info.truncated
    topics = {m.topic for m in messages}
    assert {"/camera/rgb", "/scan", "/late", "/camera/status", "/checker/status"} <= topics
    encodings = {ch.topic: (ch.encoding, ch.schema_name) for ch in info.channels.values()}
    assert encodings["/camera/rgb"] == ("cdr", "sensor_msgs/msg/Image")
    assert encodings["/scan"] == ("cdr", "sensor_msgs/msg/LaserScan")
    assert encodings["/checker/status"] == ("emos-msgpack", "sugar/msg/ComponentStatus")
    recorded = {"/camera/rgb": [], "/scan": []}
    for m in messages:
        if m.topic in recorded:
            msg = m.decode()
            assert crc_ok(msg), f"{m.topic}: recorded message {msg.header.frame_id} is corrupt"
            recorded[m.topic].append((int(msg.header.frame_id.split(":")[0]), msg.header.stamp.to_sec()))
    assert len(recorded["/camera/rgb"]) >= 30 and len(recorded["/scan"]) >= 20, {k: len(v) for k, v in recorded.items()}

    cut = BagInfo()
    survivors = [m.decode() for m in read_bag(killed_bag, info=cut)]
    assert cut.truncated, "a SIGKILLed recorder cannot have written the summary"
    assert survivors, "the complete chunks of a killed recording must be readable"
    assert all(crc_ok(m) for m in survivors)

    # Replay into a system with no sensors, only a checker.
    check_dir = tmp_path / "check"
    check_dir.mkdir()
    result = tmp_path / "checker.json"
    target = SystemUnderTest(check_dir, CHECKER_RECIPE, env={"CHECKER_OUT": str(result)}).wait_up(components=["checker"])
    play = emos("play", "--run", target.ctx.run_id, str(bag), "--topics", "/camera/rgb", "/scan")
    play_out = finish(play)
    assert "played" in play_out
    assert target.stop() == 0
    seen = json.loads(result.read_text())
    for stream, topic in (("camera", "/camera/rgb"), ("lidar", "/scan")):
        got = seen[stream]
        assert all(ok for _, ok, _, _ in got), f"{stream}: corrupt messages after replay"
        assert [s for s, *_ in got] == [s for s, _ in recorded[topic]], f"{stream}: replayed sequence differs from the recording"
        stamps = np.array([stamp for _, _, stamp, _ in got])
        arrivals = np.array([t for *_, t in got])
        span_original, span_replayed = stamps[-1] - stamps[0], arrivals[-1] - arrivals[0]
        assert abs(span_replayed - span_original) <= 0.05 * span_original, (stream, span_original, span_replayed)
        # The span (hence the mean gap) is the 5 % check. Gap by gap, the typical gap keeps its
        # length too; 10 % here, because single gaps also carry the receiver's wake-up jitter,
        # a few ms on this shared 2-core machine.
        gaps_o, gaps_r = np.diff(stamps), np.diff(arrivals)
        assert abs(np.median(gaps_r) - np.median(gaps_o)) <= 0.10 * np.median(gaps_o), (stream, np.median(gaps_o), np.median(gaps_r))
