"""Helper processes a scenario needs beside the recipe (e.g. two model servers).

Each service is a command run in its own session before the recipe starts, on a free loopback
port the runner picks (``{port}`` in the command is replaced by it; a leading ``emos`` runs this
EMOS with the current interpreter). The recipe finds it as
``EMOS_CHAOS_SERVICE_<NAME>=127.0.0.1:<port>``, and a proxy can front it with
``upstream: service:<name>``. Services are stopped (SIGTERM, then SIGKILL) when the run ends.
"""
from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from emos.errors import EmosError


class ServiceError(EmosError, RuntimeError):
    """A scenario service that could not be started (named, with its log)."""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Service:
    def __init__(self, spec: dict[str, Any], log_dir: Path) -> None:
        self.name = str(spec.get("name") or "")
        cmd = spec.get("cmd")
        if not self.name or not isinstance(cmd, list) or not cmd:
            raise ServiceError(f"a service needs 'name' and 'cmd' (a list of arguments), got {spec!r}")
        self.port = free_port()
        args = [str(a).replace("{port}", str(self.port)) for a in cmd]
        self.args = [sys.executable, "-m", "emos", *args[1:]] if args[0] == "emos" else args
        self.log = log_dir / f"service-{self.name}.log"
        self.ready_timeout = float(spec.get("ready_timeout", 60.0))
        self.proc: subprocess.Popen[bytes] | None = None

    @property
    def address(self) -> str:
        return f"127.0.0.1:{self.port}"

    def start(self) -> None:
        with open(self.log, "wb") as log:
            self.proc = subprocess.Popen(self.args, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
        deadline = time.monotonic() + self.ready_timeout
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise ServiceError(f"service {self.name!r} exited with code {self.proc.returncode} while starting; log: {self.log}")
            try:
                with socket.create_connection(("127.0.0.1", self.port), timeout=0.5):
                    return
            except OSError:
                time.sleep(0.1)
        self.stop()
        raise ServiceError(f"service {self.name!r} did not listen on {self.address} within {self.ready_timeout:.0f} s; log: {self.log}")

    def stop(self) -> None:
        if self.proc is None or self.proc.poll() is not None:
            return
        try:
            os.killpg(self.proc.pid, signal.SIGTERM)
            self.proc.wait(10)
        except subprocess.TimeoutExpired:
            os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait()
        except ProcessLookupError:
            pass
