"""The system under test: a recipe started with ``emos run`` in its own session, seen from outside.

The chaos tool is deliberately an *outside* observer, as a user's monitoring would be: it starts
the recipe as a separate process tree, finds its run through the run directory, reads the
supervision tree over the supervisor's control socket, and signals processes by pid. Nothing in
the system under test knows it is being tested.
"""
from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import psutil

from emos.core.discovery import worker_nodes
from emos.core.rpc import RpcClient
from emos.errors import EmosError
from emos.transport.context import ENV_RUN_ID, SHM_DIR, SHM_PREFIX, runtime_root


class SystemUnderTestError(EmosError, RuntimeError):
    """The recipe did not come up, or could not be observed."""


@contextlib.contextmanager
def _signals_held(*signums: int) -> Iterator[None]:
    """Hold ``signums`` (their Python handlers, which raise) until the block ends, then deliver
    them. Around a ``Popen``: a SIGTERM raised between the fork and the assignment of the
    ``Popen`` would leave the recipe running with nobody holding its pid. (Blocking them with
    the signal mask instead would be inherited by the recipe across ``exec``.)"""
    if threading.current_thread() is not threading.main_thread():
        yield  # handlers only run in the main thread; nothing to hold elsewhere
        return
    arrived: list[int] = []
    previous = {n: signal.signal(n, lambda signum, frame: arrived.append(signum)) for n in signums}
    try:
        yield
    finally:
        for n, handler in previous.items():
            signal.signal(n, handler)
        for n in dict.fromkeys(arrived):
            signal.raise_signal(n)  # now, with the Popen assigned: its handler unwinds as usual


class RunningSystem:
    """Start, observe and stop one run of a recipe."""

    def __init__(self, recipe: str | Path, duration: float, log_path: Path, env: dict[str, str] | None = None,
                 recipe_args: list[str] | None = None) -> None:
        self.recipe = Path(recipe)
        if not self.recipe.is_file():
            raise FileNotFoundError(f"chaos: recipe {self.recipe} not found")
        self.duration = float(duration)
        self.log_path = log_path
        self.env = dict(os.environ, **(env or {}))
        self.recipe_args = list(recipe_args or [])
        self.proc: subprocess.Popen[bytes] | None = None
        self.run_id: str | None = None
        self.run_dir: Path | None = None
        self.exit_code: int | None = None

    # -- life cycle -------------------------------------------------------------------------------
    def start(self, timeout: float = 60.0) -> None:
        """Start the recipe and wait until every component is up and reporting."""
        cmd = [sys.executable, "-m", "emos", "run", str(self.recipe), "--duration", str(self.duration)]
        if self.recipe_args:
            cmd += ["--", *self.recipe_args]
        # Not a `with` block: the file stays open for the recipe's whole run and wait() closes it.
        self._log = open(self.log_path, "wb")  # noqa: SIM115
        # Own session: a Ctrl-C of the chaos tool must not reach the system under test directly;
        # the tool stops it in order instead (and kills the whole group if that fails).
        with _signals_held(signal.SIGTERM, signal.SIGINT):
            self.proc = subprocess.Popen(cmd, stdout=self._log, stderr=subprocess.STDOUT, env=self.env, start_new_session=True)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise SystemUnderTestError(f"recipe {self.recipe} exited with code {self.proc.returncode} during start-up; log: {self.log_path}")
            if self.run_dir is None:
                found = sorted(runtime_root().glob(f"{self.proc.pid}-*"))
                if found and (found[0] / "supervisor.sock").exists():
                    self.run_dir, self.run_id = found[0], found[0].name
            if self.run_dir is not None:
                try:
                    answer = self.tree()
                    workers = worker_nodes(answer["tree"])
                except (OSError, ConnectionError, TimeoutError, KeyError):
                    answer, workers = {}, []
                # "up": every group started. Groups start one after another and the tree shows a
                # group only once it is up, so healthy workers alone can be the first groups only.
                if answer.get("up") and workers and all(w.get("pid") and w.get("health") == "HEALTHY" for w in workers):
                    return
            time.sleep(0.1)
        self.kill()
        raise SystemUnderTestError(f"recipe {self.recipe} did not bring all components up within {timeout:.0f} s; log: {self.log_path}")

    def wait(self, timeout: float | None = None) -> int:
        assert self.proc is not None
        try:
            self.exit_code = self.proc.wait(timeout=timeout)
        finally:
            if self.proc.returncode is not None:
                self._log.close()
        return self.exit_code

    def stop(self, timeout: float = 30.0) -> int:
        """Ask the launcher to stop (SIGINT, as Ctrl-C); kill the session if it does not."""
        if self.proc is None:
            return -1
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                return self.wait(timeout)
            except subprocess.TimeoutExpired:
                self.kill()
        return self.wait(timeout)

    def kill(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            try:
                os.killpg(self.proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            self.proc.wait()

    @property
    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    # -- observation ------------------------------------------------------------------------------
    def tree(self, timeout: float = 2.0) -> dict[str, Any]:
        if self.run_dir is None:
            raise SystemUnderTestError("the run has not been found yet")
        with RpcClient(self.run_dir / "supervisor.sock", timeout=timeout) as rpc:
            return rpc.call("tree")

    def control_socket(self, component: str) -> Path:
        """A component's control socket. Built from the path alone: constructing a RunContext
        creates the run's folders, which would resurrect the run directory of a run that just
        ended (the leak check then finds it)."""
        from emos.transport.context import encode_name

        if self.run_dir is None or not self.alive:
            raise ConnectionError("the system under test is not running")
        return self.run_dir / "ctl" / f"{encode_name(component)}.sock"

    def workers(self) -> dict[str, dict[str, Any]]:
        return {w["name"]: w for w in worker_nodes(self.tree()["tree"])}

    def pid_of(self, component: str) -> int | None:
        return self.workers().get(component, {}).get("pid")

    def launcher(self) -> psutil.Process | None:
        try:
            return psutil.Process(self.proc.pid) if self.proc else None
        except psutil.NoSuchProcess:
            return None

    def zygote_pids(self) -> list[int]:
        """The zygote and its spare: children of the launcher named ``emos:zygote``."""
        launcher = self.launcher()
        if launcher is None:
            return []
        out = []
        for child in launcher.children():
            try:
                if child.name() == "emos:zygote":
                    out.append(child.pid)
            except psutil.Error:
                pass
        return out

    def zombie_pids(self) -> set[int]:
        """Zombie descendants of the launcher right now. A process is a zombie for the instant
        between its death and its reaping, so callers count only zombies seen twice, a while apart."""
        launcher = self.launcher()
        if launcher is None:
            return set()
        out = set()
        for child in launcher.children(recursive=True):
            try:
                if child.status() == psutil.STATUS_ZOMBIE:
                    out.add(child.pid)
            except psutil.Error:
                pass
        return out

    def parents_of(self, pids: set[int]) -> dict[int, str]:
        """``pid -> "<parent pid> <parent name>"`` (to name who fails to reap a zombie)."""
        out = {}
        for pid in pids:
            try:
                parent = psutil.Process(pid).parent()
                out[pid] = f"{parent.pid} {parent.name()}" if parent else "?"
            except psutil.Error:
                out[pid] = "gone"
        return out

    def segments(self) -> list[str]:
        """Shared-memory segments of this run (while it runs, or left behind after it)."""
        if self.run_id is None:
            return []
        prefix = f"{SHM_PREFIX}{self.run_id}."
        try:
            return sorted(n for n in os.listdir(SHM_DIR) if n.startswith(prefix))
        except OSError:
            return []

    def processes(self) -> list[psutil.Process]:
        """Every live process that belongs to this run (it carries the run id in its environment)."""
        if self.run_id is None:
            return []
        out = []
        for p in psutil.process_iter():
            try:
                if p.pid != os.getpid() and p.status() != psutil.STATUS_ZOMBIE and p.environ().get(ENV_RUN_ID) == self.run_id:
                    out.append(p)
            except psutil.Error:
                continue
        return out

    def leaks(self) -> dict[str, Any]:
        """What the run left behind after it ended: segments, processes, its run directory."""
        procs = self.processes()
        return {
            "shm": len(self.segments()),
            "procs": len(procs),
            "dirs": int(self.run_dir is not None and self.run_dir.exists()),
            "detail": {"shm": self.segments()[:10], "procs": [f"{p.pid}" for p in procs[:10]],
                       "dir": str(self.run_dir) if self.run_dir and self.run_dir.exists() else None},
        }
