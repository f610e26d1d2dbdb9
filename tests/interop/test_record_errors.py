"""`emos record` when the output cannot be written: a clear message and a non-zero exit, no
traceback, no progress after the failure, and what was recorded kept as a valid MCAP file."""
from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

pytest.importorskip("mcap")
pytest.importorskip("rosbags")

from emos.interop.mcap_bag import BagInfo, read_bag
from tests.runtime.helpers import SystemUnderTest

pytestmark = pytest.mark.process

CAMERA = """
class Camera(BaseComponent):
    def _execution_step(self):
        self.publish("camera/rgb", M.Image.from_numpy(np.full((64, 64, 3), 9, np.uint8), "rgb8"))  # 12 KiB
        self.health_status.set_healthy()

camera = Camera(component_name="camera", outputs=[Topic(name="camera/rgb", msg_type="Image")])
camera.config.loop_rate = 20.0
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[camera])
launcher.bringup()
"""


def emos(*args: str, timeout: float = 120) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "emos", *args], capture_output=True, text=True, timeout=timeout)


def assert_one_clean_line(proc: subprocess.CompletedProcess, *words: str) -> str:
    assert proc.returncode != 0, proc
    assert "Traceback" not in proc.stderr, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert lines, proc
    for w in words:
        assert w in lines[-1], proc.stderr
    return lines[-1]


@pytest.fixture
def tmpfs():
    """A fresh tmpfs of the given options, unmounted afterwards; skips the test when we may not mount."""
    mounts: list[str] = []

    def mount(options: str) -> Path:
        where = tempfile.mkdtemp(prefix="emos-rec-")
        out = subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", where], capture_output=True, text=True)
        if out.returncode != 0:
            os.rmdir(where)
            pytest.skip(f"cannot mount a tmpfs here: {out.stderr.strip()}")
        mounts.append(where)
        return Path(where)

    yield mount
    for where in mounts:
        subprocess.run(["umount", "-l", where], check=False)
        os.rmdir(where)


@pytest.mark.parametrize("args, message", [
    (["--duration", "nan"], "--duration must be > 0"),
    (["--duration", "inf"], "--duration must be > 0"),
    (["--duration", "-1"], "--duration must be > 0"),
    (["--chunk-size", "0"], "--chunk-size must be 1024..268435456"),
    (["--chunk-size", "-5"], "--chunk-size must be 1024..268435456"),
    (["--chunk-size", str(1 << 40)], "--chunk-size must be 1024..268435456"),
])
def test_bad_duration_and_chunk_size_are_usage_errors(tmp_path, args, message):
    out = emos("record", "-o", str(tmp_path / "x.mcap"), *args)
    assert out.returncode == 2  # argparse's usage error, before anything starts
    assert_one_clean_line(out, message)
    assert not (tmp_path / "x.mcap").exists()


def test_unwritable_output_is_named_before_recording(tmp_path, tmpfs):
    # No running system is needed: the path is checked first.
    assert_one_clean_line(emos("record", "-o", "/etc/passwd/x.mcap"), "/etc/passwd/x.mcap", "/etc/passwd is not a directory")
    assert_one_clean_line(emos("record", "-o", str(tmp_path / "no" / "x.mcap")), "does not exist", str(tmp_path / "no"))
    assert_one_clean_line(emos("record", "-o", str(tmp_path)), "is a directory")
    ro = tmpfs("ro,size=64k")
    assert_one_clean_line(emos("record", "-o", str(ro / "x.mcap")), str(ro), "not writable", "read-only")


def test_write_errors_stop_the_recording_with_one_line(tmp_path, tmpfs):
    system = SystemUnderTest(tmp_path, CAMERA).wait_up(components=["camera"])
    run = system.ctx.run_id
    try:
        # A path the checks pass (root may write to /proc) but that cannot be created.
        out = emos("record", "--run", run, "-o", "/proc/emos-test-record.mcap", "--duration", "5")
        assert_one_clean_line(out, "cannot write /proc/emos-test-record.mcap", "No such file or directory")

        # Every write fails: a message, not a traceback, and no progress after it.
        out = emos("record", "--run", run, "-o", "/dev/full", "--force", "--chunk-size", "1024", "--duration", "60")
        line = assert_one_clean_line(out, "writing /dev/full failed", "No space left on device (ENOSPC)", "not a regular file")
        assert out.stderr.rstrip().endswith(line)

        # A full disk: the recorder stops by itself (no --duration), and the file holds what fit, closed properly.
        disk = tmpfs("size=64k")
        bag = disk / "full.mcap"
        out = emos("record", "--run", run, "/camera/rgb", "-o", str(bag), "--chunk-size", "4096")
        line = assert_one_clean_line(out, f"writing {bag} failed", "No space left on device (ENOSPC)", "valid MCAP file")
        assert out.stderr.rstrip().endswith(line), out.stderr  # no progress line after the error
        assert bag.read_bytes().endswith(b"\x89MCAP0\r\n")  # footer and closing magic written
        info = BagInfo()
        images = [m.decode() for m in read_bag(bag, info=info)]
        assert images and not info.truncated, info
        assert all(img.height == 64 and (img.data == 9).all() for img in images)
        from mcap.reader import make_reader

        with open(bag, "rb") as f:  # the MCAP library's own reader agrees
            assert sum(1 for _ in make_reader(f).iter_messages()) == len(images)
    finally:
        assert system.stop() == 0
