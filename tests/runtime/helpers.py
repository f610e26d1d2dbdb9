"""Running real EMOS systems from tests: a recipe in a subprocess, reached through its sockets."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import psutil

from emos.core.rpc import RpcClient
from emos.transport.context import SHM_DIR, RunContext, runtime_root

REPO = Path(__file__).resolve().parents[2]

RECIPE_HEADER = """
import os, sys, time, signal
import numpy as np
from emos import BaseComponent, Launcher, Topic
from emos import msgs as M
"""

# A run whose one component reads the String topic /shared (the CLI tests publish on it).
LISTENER = """
class Listener(BaseComponent):
    def _execution_step(self):
        self.get_input("/shared")
        self.health_status.set_healthy()

c = Listener(component_name="listener", inputs=[Topic(name="/shared", msg_type="String")])
c.config.loop_rate = 20.0
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[c])
launcher.bringup()
"""


# The default waits of these helpers only bound a hang: a condition that holds returns at once, so
# they are generous (a loaded machine takes many times longer to restart a process than an idle
# one, and a test must not depend on the machine being idle).
HANG_S = 60.0


def wait_until(pred: Callable[[], Any], timeout: float = HANG_S, interval: float = 0.02, what: str = "condition") -> Any:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        value = pred()
        if value:
            return value
        time.sleep(interval)
    raise AssertionError(f"timed out after {timeout} s waiting for {what}")


_STARTED: list[SystemUnderTest] = []


def shm_in_use(pid: int | None = None) -> set[str]:
    """Names of the /dev/shm files that process ``pid`` (every process when None) maps or holds
    open. A segment nobody uses is a leak; one that another test's live process uses is not (the
    suite runs tests side by side: pytest -n 2)."""
    pids = [pid] if pid is not None else [int(d) for d in os.listdir("/proc") if d.isdigit()]
    used: set[str] = set()
    for p in pids:
        try:
            with open(f"/proc/{p}/maps") as f:
                used.update(line.split("/dev/shm/", 1)[1].split(" (deleted)")[0].strip() for line in f if "/dev/shm/" in line)
            for fd in os.listdir(f"/proc/{p}/fd"):
                target = os.readlink(f"/proc/{p}/fd/{fd}")
                if target.startswith("/dev/shm/"):
                    used.add(target[len("/dev/shm/"):].split(" (deleted)")[0])
        except OSError:  # the process ended, or is not ours to read
            continue
    return used


def kill_leftover_systems() -> None:
    """Called after every test (tests/runtime/conftest.py): no test leaves a system running."""
    while _STARTED:
        _STARTED.pop().kill_all()


def ctrl_c_as_at_a_terminal() -> None:
    """``preexec_fn`` for a child the test will Ctrl-C (SIGINT): a background job of a
    non-interactive shell (``pytest ... &``, CI wrappers) inherits SIGINT ignored, and a Python
    started that way keeps ignoring it (no KeyboardInterrupt): give the child a terminal's
    default back."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


class SystemUnderTest:
    """A recipe running under ``emos run`` in its own process."""

    def __init__(self, tmp_path: Path, body: str, duration: float | None = None, env: dict | None = None, prefix: list[str] | None = None,
                 args: list[str] | None = None, python: str | None = None):
        """``prefix``: a command that execs the rest in place (``ip netns exec NS``), keeping the pid.
        ``args``: more options of ``emos run`` (``--ros2``, ...). ``python``: another interpreter
        than this one (a venv with other packages, e.g. another ROS 2 distribution's wheels)."""
        _STARTED.append(self)
        self.script = tmp_path / "recipe.py"
        self.script.write_text(RECIPE_HEADER + textwrap.dedent(body))
        cmd = [*(prefix or []), python or sys.executable, "-m", "emos", "run", str(self.script)]
        if duration:
            cmd += ["--duration", str(duration)]
        cmd += args or []
        self.log_path = tmp_path / "system.log"
        self._log = open(self.log_path, "wb")  # noqa: SIM115 - open while the system runs; stop/wait_exit/kill_all close it
        self.proc = subprocess.Popen(cmd, stdout=self._log, stderr=subprocess.STDOUT, env={**os.environ, **(env or {})}, cwd=tmp_path)
        self.run_dir: Path | None = None
        self.ctx: RunContext | None = None
        self.rpc: RpcClient | None = None

    def wait_up(self, timeout: float = 2 * HANG_S, components: list[str] | None = None) -> SystemUnderTest:
        def find() -> Path | None:
            if self.proc.poll() is not None:
                raise AssertionError(f"system exited early with {self.proc.returncode}:\n{self.output()}")
            for d in runtime_root().iterdir():
                if d.name.startswith(f"{self.proc.pid}-") and (d / "supervisor.sock").exists():
                    return d
            return None

        self.run_dir = wait_until(find, timeout, what="the system's run directory")
        self.ctx = RunContext(self.run_dir.name, self.run_dir, owner=False)
        self.rpc = RpcClient(self.run_dir / "supervisor.sock")
        if components:
            wait_until(lambda: all(self.state(c) == "active" for c in components), timeout, what=f"{components} active")
        return self

    def tree(self) -> dict:
        assert self.rpc is not None
        return self.rpc.call("tree")["tree"]

    def workers(self) -> dict[str, dict]:
        out = {}

        def walk(node: dict) -> None:
            if node.get("kind") == "worker" or node.get("state") == "stopped":
                out[node["name"]] = node
            for child in node.get("children", []):
                walk(child)

        walk(self.tree())
        return out

    def pid(self, name: str) -> int | None:
        return self.workers().get(name, {}).get("pid")

    def state(self, name: str) -> str | None:
        return self.workers().get(name, {}).get("state")

    def events(self, since: float = 0.0) -> list[dict]:
        assert self.rpc is not None
        return self.rpc.call("events", since=since)

    def wait_new_pid(self, name: str, old: int | None, timeout: float = HANG_S) -> int:
        def new() -> int | None:
            w = self.workers().get(name, {})
            pid = w.get("pid")
            return pid if pid and pid != old and w.get("state") == "active" else None

        return wait_until(new, timeout, what=f"{name} restarted with a new pid")

    def stop(self, sig: int = signal.SIGTERM, timeout: float = 30.0) -> int:
        if self.rpc is not None:
            self.rpc.close()
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
        try:
            return self.proc.wait(timeout)
        finally:
            self._log.close()

    def wait_exit(self, timeout: float = 30.0) -> int:
        try:
            return self.proc.wait(timeout)
        finally:
            self._log.close()

    def output(self) -> str:
        if not self._log.closed:
            self._log.flush()
        return self.log_path.read_text(errors="replace")

    def leftovers(self) -> list[str]:
        """Shared-memory segments, run directory and processes the run left behind."""
        prefix = self.ctx.shm_prefix if self.ctx else f"emos.{self.proc.pid}-"
        left = [n for n in os.listdir(SHM_DIR) if n.startswith(prefix)]
        if self.ctx is None:
            left += [str(d) for d in runtime_root().iterdir() if d.name.startswith(f"{self.proc.pid}-")]
            return left
        if self.run_dir is not None and self.run_dir.exists():
            left.append(str(self.run_dir))
        # A zygote and its workers are forks of the launcher: they carry its command line (the
        # test's own recipe path) but not EMOS_RUN_ID, which the launcher set after it started
        # (/proc/<pid>/environ shows a process's environment as it was exec'd).
        script = str(self.script)
        for p in psutil.process_iter(["name"]):
            if p.info["name"] and p.info["name"].startswith("emos:"):
                try:
                    ours = script in p.cmdline() or p.environ().get("EMOS_RUN_ID") == self.ctx.run_id
                    if ours and p.status() != psutil.STATUS_ZOMBIE:
                        left.append(f"process {p.pid} {p.info['name']}")
                except psutil.Error:
                    pass
        return left

    def kill_all(self) -> None:
        """SIGKILL the launcher; its workers and zygotes follow it (parent-death signal)."""
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        if not self._log.closed:
            self._log.close()
