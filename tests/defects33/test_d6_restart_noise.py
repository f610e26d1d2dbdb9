"""Issue 33 D6: a threaded run copies its components for real (fresh locks, pristine state at
each restart) instead of printing "cannot deep-copy the component (cannot pickle
'_thread.lock' object)" and reusing the object; a restart's first beats are its own, not "status
from ring ... does not count as its heartbeat"."""
from __future__ import annotations

import queue
import socket
import threading

import pytest

from emos.ratelimit import RateLimitedLog
from emos.supervisor.pristine import pristine_copy
from tests.runtime.helpers import SystemUnderTest, wait_until

NOISE = ("cannot deep-copy", "cannot copy the component", "does not count as its heartbeat")


class _Holder:
    component_name = "holder"

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.same_lock = self.lock
        self.rlock = threading.RLock()
        self.event = threading.Event()
        self.queue: queue.Queue[int] = queue.Queue()
        self.log = RateLimitedLog(interval=5.0)
        self.state = [1, 2]


@pytest.mark.unit
def test_pristine_copy_gives_fresh_working_locks():
    original = _Holder()
    original.lock.acquire()
    original.event.set()
    clone = pristine_copy(original)
    assert clone is not original and clone.state == [1, 2] and clone.state is not original.state
    assert clone.lock is not original.lock and clone.lock is clone.same_lock  # sharing is kept
    assert not clone.lock.locked() and original.lock.locked()
    assert clone.rlock is not original.rlock and clone.rlock.acquire(timeout=1)
    # a Condition keeps its lock's methods: they must be the new lock's (Queue, Event build on it)
    assert clone.queue.mutex is not original.queue.mutex and clone.queue.not_empty.acquire.__self__ is clone.queue.mutex
    clone.queue.put(7)
    assert clone.queue.get(timeout=1) == 7 and original.queue.empty()
    assert clone.event.is_set()
    clone.event.clear()
    assert original.event.is_set()


@pytest.mark.unit
def test_pristine_copy_names_what_cannot_be_copied(caplog):
    holder = _Holder()
    holder.sock = socket.socket()
    try:
        with caplog.at_level("WARNING", logger="emos.supervisor"):
            assert pristine_copy(holder) is holder
        assert "[holder] cannot copy the component for restarts in threaded mode (attribute 'sock'" in caplog.text
    finally:
        holder.sock.close()


RECIPE = """
from pathlib import Path
from emos.ratelimit import RateLimitedLog

class CrashOnce(BaseComponent):
    def __init__(self, **kw):
        super().__init__(**kw)
        self.activations = 0  # pristine state: 0 in every fresh incarnation
        self.flag = __import__("threading").Event()
        self.noise = RateLimitedLog(interval=5.0)

    def custom_on_activate(self):
        self.activations += 1
        self.t0 = time.monotonic()
        Path(f"{self.component_name}.activations").open("a").write(f"{self.activations}\\n")

    def _execution_step(self):
        self.health_status.set_healthy()
        marker = Path(f"{self.component_name}.crashed")
        if not marker.exists() and time.monotonic() - self.t0 > 0.5:
            marker.touch()
            self.node.request_exit(1)

threaded = CrashOnce(component_name="threaded")
forked = CrashOnce(component_name="forked")
for c in (threaded, forked):
    c.config.loop_rate = 20.0
launcher = Launcher(max_restarts=5, max_seconds=60)
launcher.add_pkg(components=[threaded], package_name="threads", multiprocessing=False)
launcher.add_pkg(components=[forked], package_name="processes", multiprocessing=True)
launcher.bringup()
"""


@pytest.mark.process
def test_threaded_run_and_restarts_print_no_copy_or_foreign_heartbeat_noise(tmp_path):
    system = SystemUnderTest(tmp_path, RECIPE).wait_up(components=["threaded", "forked"])
    try:
        restarted = lambda name: [e for e in system.events() if e["event"] == "restarted" and e["child"] == name]  # noqa: E731
        wait_until(lambda: restarted("threaded") and restarted("forked"), what="a restart of each component")
        wait_until(lambda: system.state("threaded") == "active" and system.state("forked") == "active", what="both active again")
        assert system.workers()["threaded"]["mode"] == "thread"
    finally:
        assert system.stop() == 0
    out = system.output()
    assert not [line for line in out.splitlines() if any(n in line for n in NOISE)], out[-3000:]
    # Each incarnation started from the component as defined: the threaded restart ran a fresh
    # copy, not the crashed object with its state.
    for name in ("threaded", "forked"):
        assert (tmp_path / f"{name}.activations").read_text().split() == ["1", "1"], name
