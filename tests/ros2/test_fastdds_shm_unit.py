"""emos.interop.ros2.fastdds_shm: which Fast DDS files count as left behind (in a temporary
directory standing for /dev/shm; the lock holder is a real second process)."""
from __future__ import annotations

import fcntl
import os
import subprocess
import sys
import time

import pytest

from emos.interop.ros2.fastdds_shm import remove_leftovers

pytestmark = pytest.mark.unit


def _segment(d, base: str, age_s: float = 60.0) -> None:
    for name in (base, f"sem.{base}_mutex", f"{base}_el"):
        path = d / name
        path.write_bytes(b"x")
        then = time.time() - age_s
        os.utime(path, (then, then))


def test_a_segment_whose_lock_nobody_holds_is_removed_with_its_semaphore(tmp_path):
    _segment(tmp_path, "fastrtps_0123456789abcdef")
    _segment(tmp_path, "fastrtps_port7413")
    (tmp_path / "emos.other").write_bytes(b"x")  # not Fast DDS's
    removed = remove_leftovers(str(tmp_path), min_age_s=5.0)
    assert sorted(removed) == sorted(["fastrtps_0123456789abcdef", "sem.fastrtps_0123456789abcdef_mutex", "fastrtps_0123456789abcdef_el",
                                      "fastrtps_port7413", "sem.fastrtps_port7413_mutex", "fastrtps_port7413_el"])
    assert sorted(os.listdir(tmp_path)) == ["emos.other"]


def test_a_segment_a_live_process_holds_is_kept(tmp_path):
    _segment(tmp_path, "fastrtps_live")
    holder = subprocess.Popen([sys.executable, "-c", "import fcntl, os, sys, time\n"
                               f"fd = os.open({str(tmp_path / 'fastrtps_live_el')!r}, os.O_RDONLY)\n"
                               "fcntl.flock(fd, fcntl.LOCK_SH)\nprint('held', flush=True)\ntime.sleep(60)"],
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "held"
        assert remove_leftovers(str(tmp_path), min_age_s=5.0) == []
        assert len(os.listdir(tmp_path)) == 3
    finally:
        holder.kill()
        holder.wait()
    # The holder gone (SIGKILL releases its lock): now a leftover.
    assert len(remove_leftovers(str(tmp_path), min_age_s=5.0)) == 3


def test_young_files_symlinks_and_files_without_a_lock_file_are_left_alone(tmp_path):
    _segment(tmp_path, "fastrtps_young", age_s=0.0)  # its owner may be about to lock it
    (tmp_path / "fastrtps_port9").write_bytes(b"x")  # no lock file: not ours to judge
    target = tmp_path / "elsewhere"
    target.write_bytes(b"x")
    os.symlink(target, tmp_path / "fastrtps_link_el")
    assert remove_leftovers(str(tmp_path), min_age_s=5.0) == []
    assert target.exists() and (tmp_path / "fastrtps_port9").exists()


def test_our_lock_is_released_after_removal(tmp_path):
    _segment(tmp_path, "fastrtps_gone")
    remove_leftovers(str(tmp_path), min_age_s=5.0)
    # A new participant can create and lock the same name at once.
    fd = os.open(tmp_path / "fastrtps_gone_el", os.O_RDWR | os.O_CREAT)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    finally:
        os.close(fd)


SWEEP_AGAIN = """
import os, sys, time
from emos.interop.ros2.fastdds import choose_transports
from emos.transport.context import RunContext

base = sys.argv[1]
for name in (base, base + "_el"):  # a predecessor's files, seconds old: too young for the first sweep
    open(os.path.join("/dev/shm", name), "wb").close()
choose_transports(RunContext.create(), "shm")
print("after the first sweep:", os.path.exists(os.path.join("/dev/shm", base + "_el")), flush=True)
time.sleep(120)
"""


def test_a_participant_sweeps_again_once_young_leftovers_are_old_enough():
    """A participant SIGKILLed within seconds of its start and restarted at once leaves files the
    restart's first sweep must skip (they may belong to a participant that has not locked them
    yet); the restarted participant sweeps again when they are old enough."""
    base = f"fastrtps_emostest{os.getpid():x}"
    proc = subprocess.Popen([sys.executable, "-c", SWEEP_AGAIN, base], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        assert proc.stdout.readline().strip() == "after the first sweep: True"
        deadline = time.monotonic() + 60.0  # bounds a hang only: the second sweep is due 6 s after the first
        while os.path.exists(f"/dev/shm/{base}_el") and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not os.path.exists(f"/dev/shm/{base}_el") and not os.path.exists(f"/dev/shm/{base}")
    finally:
        proc.kill()
        proc.wait()
        for name in (base, base + "_el"):
            if os.path.exists(f"/dev/shm/{name}"):
                os.unlink(f"/dev/shm/{name}")
