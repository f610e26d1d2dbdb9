"""The launcher's patience with a zygote: one that is slow to answer but runnable (a starved
machine) is waited for; one that is stopped is given up after the first SPAWN_TIMEOUT_S; one that
runs without ever answering is given up after ZYGOTE_HANG_S. The zygote here is a real process
on the other end of the real channel, speaking the zygote's framing."""
from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time

import pytest

from emos.supervisor import spawn

pytestmark = pytest.mark.process

PEER = r"""
import os, socket, sys, time
from emos.supervisor.spawn import _recv, _send
sock = socket.socket(fileno=int(sys.argv[1]))
request = _recv(sock)
time.sleep(float(sys.argv[2]))
_send(sock, {"pid": os.getpid(), "op": request["op"]})
sock.recv(1)  # until the test closes its end
"""


@pytest.fixture
def zygote():
    """A peer answering after ``delay`` s: yields ``start(delay) -> (handle, process)``."""
    started: list[tuple[spawn._ZygoteHandle, subprocess.Popen]] = []

    def start(delay: float) -> tuple[spawn._ZygoteHandle, subprocess.Popen]:
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
        proc = subprocess.Popen([sys.executable, "-c", PEER, str(theirs.fileno()), str(delay)], pass_fds=[theirs.fileno()])
        theirs.close()
        handle = spawn._ZygoteHandle(proc.pid, ours, direct_child=False)
        started.append((handle, proc))
        return handle, proc

    yield start
    for handle, proc in started:
        proc.kill()
        handle.sock.close()
        proc.wait()


def test_a_slow_but_runnable_zygote_is_waited_for(zygote):
    handle, proc = zygote(spawn.SPAWN_TIMEOUT_S + 1.5)  # answers after the old 2 s give-up
    reply, _ = handle.request({"op": "spawn", "index": 0})
    assert reply == {"pid": proc.pid, "op": "spawn"}


def test_a_stopped_zygote_is_given_up_after_the_first_timeout(zygote):
    handle, proc = zygote(600.0)
    os.kill(proc.pid, signal.SIGSTOP)
    with pytest.raises(TimeoutError, match=f"did not answer within {spawn.SPAWN_TIMEOUT_S:g} s and is stopped or gone"):
        handle.request({"op": "spawn", "index": 0})
    os.kill(proc.pid, signal.SIGCONT)


def test_a_zygote_that_runs_but_never_answers_is_given_up_as_hung(zygote, monkeypatch):
    monkeypatch.setattr(spawn, "ZYGOTE_HANG_S", 2 * spawn.SPAWN_TIMEOUT_S)
    handle, _ = zygote(600.0)
    with pytest.raises(TimeoutError, match="although it runs"):
        handle.request({"op": "spawn", "index": 0})


def test_a_spare_not_yet_adopted_is_not_taken_for_dead():
    """A cloned spare is its intermediate's child for a moment after birth (longer on a loaded
    machine): ``replace_dead`` cannot wait for it yet, and must not take that for its death. A
    spare that no longer exists at all is replaced."""
    # A live process that is not our child: its parent shell exits at once.
    out = subprocess.run(["sh", "-c", "sleep 60 >/dev/null 2>&1 & echo $!"], capture_output=True, text=True, check=True)
    orphan = int(out.stdout.strip())
    ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        zygote = spawn.Zygote([], [])
        zygote.spare = handle = spawn._ZygoteHandle(orphan, ours, direct_child=False)
        zygote.replace_dead()
        assert zygote.spare is handle  # alive, only not ours (yet): kept
        os.kill(orphan, signal.SIGKILL)
        for _ in range(500):  # until init has reaped it
            if spawn.proc_stat(orphan) is None:
                break
            time.sleep(0.01)
        zygote.replace_dead()
        assert zygote.spare is None  # gone: replaced (no primary to clone from here)
    finally:
        theirs.close()
        try:
            os.kill(orphan, signal.SIGKILL)
        except ProcessLookupError:
            pass
