"""ROS 2 tests: real rclpy programs (tests/ros2/peers) beside real EMOS runs.

Skipped, with the reason, only when this Python has no ROS 2 (scripts/setup.sh --test installs
the Jazzy wheels, so CI runs them). Discovery stays on this host (ROS_AUTOMATIC_DISCOVERY_RANGE),
and each module uses its own random domain ids, so nothing here meets another run's nodes.
"""
from __future__ import annotations

import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import pytest

from emos.interop.ros2 import env
from tests.runtime.helpers import HANG_S

PEERS = Path(__file__).parent / "peers"
REPO = Path(__file__).resolve().parents[2]

if env.find() is None:
    pytest.skip("ROS 2 is not installed in this Python (pip install 'emos[ros2]', or scripts/setup.sh --test)", allow_module_level=True)

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"  # inherited by every run and peer of the tests


def fastdds_files() -> set[str]:
    """Fast DDS's /dev/shm files that no live process maps or holds open: what a dead node left
    behind (a live node's files, this test's or another test's beside it, are not leftovers)."""
    from tests.runtime.helpers import shm_in_use

    found = fastdds_names()
    return found - shm_in_use() if found else found


def fastdds_names() -> set[str]:
    """Every Fast DDS /dev/shm file now, owned or not: a test's "before". Taking only the unowned
    ones there would blame the test for a file whose owner (an earlier test's node) was still
    alive when it started and died during it."""
    return {n for n in os.listdir("/dev/shm") if "fastrtps" in n or "fastdds" in n}


_CLAIMED: list[int] = []  # lock files held for this process's life: its domains are its own


def free_domains(n: int) -> list[int]:
    """``n`` ROS 2 domain ids no other test process on this machine holds (a lock file per domain,
    kept until this process ends): two runs on one domain would see each other's nodes."""
    import fcntl

    got: list[int] = []
    for domain in random.sample(range(20, 100), 80):
        fd = os.open(os.path.join(tempfile.gettempdir(), f"emos-test-ros-domain-{domain}.lock"), os.O_RDWR | os.O_CREAT, 0o600)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            continue
        _CLAIMED.append(fd)
        got.append(domain)
        if len(got) == n:
            return got
    raise RuntimeError(f"no free ROS 2 domain for this test: {len(got)} of {n} found among 20-99")


def _report_to_parent(target, args: tuple, conn) -> None:
    """In the forked child: send ``target(*args)``'s dict, or the traceback as "error", and exit
    without running the parent's atexit handlers (pytest's, rclpy's)."""
    import traceback

    try:
        conn.send(target(*args))
    except BaseException:
        conn.send({"error": traceback.format_exc()})
    finally:
        conn.close()
        os._exit(0)


def forked_child_result(target, *args, what: str = "the child") -> dict:
    """Run ``target(*args)`` in a forked process (a process of its own, as a bridge or an EMOS
    component runs, with rclpy started there) and return the dict it returns. The child is reaped
    on every path; an exception in it fails the test with its traceback."""
    import multiprocessing as mp

    ours, theirs = mp.get_context("fork").Pipe(duplex=False)
    child = mp.get_context("fork").Process(target=_report_to_parent, args=(target, args, theirs))
    child.start()
    theirs.close()
    try:
        assert ours.poll(6 * HANG_S), f"{what} reported nothing"
        got = ours.recv()
    finally:
        child.join(HANG_S)
        if child.is_alive():
            child.kill()
            child.join()
    assert "error" not in got, got.get("error")
    return got


@pytest.hookimpl(tryfirst=True)  # before pytest-xdist's own hook reads the groups into the test ids
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The ROS 2 tests run in one worker under pytest-xdist (--dist loadgroup): their checks for
    Fast DDS files left behind look at the whole of /dev/shm, which another ROS 2 test beside
    them would change."""
    here = Path(__file__).parent
    for item in items:
        if here in Path(str(item.fspath)).parents:
            item.add_marker(pytest.mark.xdist_group("ros2"))


class Peer:
    """A plain rclpy program from tests/ros2/peers, its output lines collected as they come."""

    def __init__(self, script: str, *args: object, udp_only: bool = True):
        """``udp_only`` (the default): Fast DDS without shared memory (loopback UDP). A peer that
        dies before destroying its node (SIGKILLed, or stopped while rclpy starts under load)
        would leave /dev/shm/fastrtps_* behind as any ROS 2 node does, and the tests' leftover
        checks are there to catch what EMOS leaves, not the peers: with UDP peers any Fast DDS
        file that appears is EMOS's. ``udp_only=False`` for a peer that must use shared memory."""
        environ = dict(os.environ)
        if udp_only:
            from emos.interop.ros2.fastdds import UDP_LOOPBACK_PROFILE

            profile = Path(tempfile.mkdtemp(prefix="emos-ros2-peer-")) / "udp.xml"
            profile.write_text(UDP_LOOPBACK_PROFILE)
            environ.pop("ROS_AUTOMATIC_DISCOVERY_RANGE", None)
            environ["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(profile)
            self._profile_dir = profile.parent
        self.proc = subprocess.Popen([sys.executable, str(PEERS / script), *map(str, args)], stdout=subprocess.PIPE,
                                     stderr=subprocess.STDOUT, text=True, cwd=PEERS, env=environ)
        self.lines: list[str] = []
        self._cond = threading.Condition()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        _PEERS.append(self)

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            with self._cond:
                self.lines.append(line.rstrip("\n"))
                self._cond.notify_all()

    def wait_for(self, pred, timeout: float = HANG_S, what: str = "a line") -> str:
        end = time.monotonic() + timeout
        seen = 0
        with self._cond:
            while True:
                for line in self.lines[seen:]:
                    if pred(line):
                        return line
                seen = len(self.lines)
                left = end - time.monotonic()
                if left <= 0 or (self.proc.poll() is not None and seen == len(self.lines)):
                    raise AssertionError(f"peer {self.proc.args[1:]}: no {what} (exit {self.proc.poll()}); output:\n" + "\n".join(self.lines[-40:]))
                self._cond.wait(min(left, 0.2))

    def got(self) -> list[str]:
        with self._cond:
            return [line for line in self.lines if line.startswith("got ")]

    def stop(self, sig: int = signal.SIGTERM) -> int:
        if self.proc.poll() is None and sig != signal.SIGKILL:
            # A peer signalled while rclpy starts (before its try/finally) dies with its Fast DDS
            # participant undestroyed, leaving /dev/shm/fastrtps_* that the tests' leftover checks
            # then see: let it reach "ready" (or exit) first. (A robot peer says "ready: domain ...".)
            try:
                self.wait_for(lambda line: line == "ready" or line.startswith("ready:"), what="ready before being stopped")
            except AssertionError:
                pass  # it exited, or never got ready: stop it as it is
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
            try:
                self.proc.wait(20)
            except subprocess.TimeoutExpired:
                self.proc.kill()
        code = self.proc.wait()
        if getattr(self, "_profile_dir", None) is not None:
            shutil.rmtree(self._profile_dir, ignore_errors=True)
        return code


_PEERS: list[Peer] = []


@pytest.fixture(autouse=True)
def _nothing_outlives_its_test():
    yield
    while _PEERS:
        _PEERS.pop().stop()
