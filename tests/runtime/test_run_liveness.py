"""A run is alive while its launcher process is: the run id's start token must not change for a
live process. It did when it was psutil's create_time() in 1/100 s of the epoch, which adds
/proc/stat's btime (whole seconds, moved by a clock adjustment): every live run then looked dead
at once and the next launcher's sweep removed their directories. Now it is the process's start
in clock ticks since boot (/proc/PID/stat), which no clock change moves."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from emos.transport import context

pytestmark = [pytest.mark.unit, pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="Linux /proc only")]


def test_a_live_run_stays_alive_when_the_boot_time_moves(monkeypatch):
    run_id = context.make_run_id()
    assert context.run_is_alive(run_id)
    from psutil import _pslinux

    real = _pslinux.boot_time
    monkeypatch.setattr(_pslinux, "boot_time", lambda: real() + 1.0)  # the clock was adjusted by a second
    assert context.run_is_alive(run_id)


def test_a_process_that_ended_is_not_alive_and_a_new_pid_is_another_process():
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        run_id = context.make_run_id(child.pid)
        assert context.run_is_alive(run_id)
        pid, token = run_id.split("-")
        assert not context.run_is_alive(f"{pid}-{int(token) + 1}")  # same pid, another start
    finally:
        child.kill()
        child.wait()
    assert not context.run_is_alive(run_id)
    assert context._start_token(child.pid) is None


def test_the_stat_line_is_read_after_the_last_parenthesis(tmp_path, monkeypatch):
    """The command name may hold spaces and parentheses; a zombie is no live process."""
    (tmp_path / "4242").mkdir()
    fields = ["S", "1", "4242", "4242", "0", "-1", "4194560", "0", "0", "0", "0", "0", "0", "0", "0", "20", "0", "1", "0",
              "987654"]
    (tmp_path / "4242" / "stat").write_text("4242 (a) b (c)) " + " ".join(fields) + " 1 2 3\n")
    monkeypatch.setattr(context, "_PROC", tmp_path)
    assert context._start_token(4242) == 987654
    (tmp_path / "4242" / "stat").write_text("4242 (x) " + " ".join(["Z"] + fields[1:]) + "\n")
    assert context._start_token(4242) is None
    assert context._start_token(4343) is None  # no such entry
