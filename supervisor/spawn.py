"""Starting component processes fast and safely, and learning of their death at once.

* **Zygote.** At bring-up, before the launcher starts any thread or event loop, it forks a
  *zygote*: a single-threaded copy of the recipe process holding every component object as the
  recipe built it. Each (re)start asks the zygote to fork. No re-import of the recipe (so
  recipes need no ``__main__`` guard and may define callables anywhere), no pickling of
  components, and no fork of a process that runs threads.
* **Double fork + subreaper.** The zygote forks an intermediate that forks the worker and exits
  at once. The launcher has marked itself ``PR_SET_CHILD_SUBREAPER``, so the orphaned worker is
  re-parented to the launcher, which alone reaps it and reads its exit status.
* **pidfd.** The launcher watches a ``pidfd`` of every worker in its event loop: death is
  known the moment the kernel reaps the task, with no polling.
* **Parent death.** Workers and the zygote set ``PR_SET_PDEATHSIG`` to the launcher: if the
  launcher is SIGKILLed they get SIGTERM, and the zygote then removes the run's shared memory.
"""
from __future__ import annotations

import asyncio
import ctypes
import logging
import os
import signal
import socket
import struct
import sys
import threading
import time
from typing import Any, Callable

import msgpack

log = logging.getLogger("emos.supervisor")

PR_SET_NAME = 15
PR_SET_PDEATHSIG = 1
PR_SET_CHILD_SUBREAPER = 36
_LEN = struct.Struct("<I")

try:
    _libc = ctypes.CDLL(None, use_errno=True)
except OSError:  # pragma: no cover - non-glibc systems
    _libc = None


def prctl(option: int, arg: int | bytes) -> None:
    if _libc is None:
        raise OSError("prctl is not available on this platform")
    if _libc.prctl(option, arg if isinstance(arg, bytes) else ctypes.c_ulong(arg), 0, 0, 0) != 0:
        err = ctypes.get_errno()
        raise OSError(err, os.strerror(err))


def become_subreaper() -> None:
    prctl(PR_SET_CHILD_SUBREAPER, 1)


def set_process_name(name: str) -> None:
    """What ``ps``/``top`` show (15 bytes max): ``emos:<component>``."""
    try:
        prctl(PR_SET_NAME, name.encode()[:15])
    except OSError:
        pass


def die_with(parent_pid: int, sig: int = signal.SIGTERM) -> bool:
    """Ask for ``sig`` when ``parent_pid`` dies; False if it is already gone (or not our parent)."""
    prctl(PR_SET_PDEATHSIG, sig)
    return os.getppid() == parent_pid


def _send(sock: socket.socket, obj: Any) -> None:
    body = msgpack.packb(obj, use_bin_type=True)
    sock.sendall(_LEN.pack(len(body)) + body)


def _recv(sock: socket.socket) -> Any:
    head = b""
    while len(head) < 4:
        chunk = sock.recv(4 - len(head))
        if not chunk:
            raise EOFError("zygote channel closed")
        head += chunk
    (n,) = _LEN.unpack(head)
    body = b""
    while len(body) < n:
        chunk = sock.recv(n - len(body))
        if not chunk:
            raise EOFError("zygote channel closed")
        body += chunk
    return msgpack.unpackb(body, raw=False)


class ZygoteError(RuntimeError):
    pass


class Zygote:
    """Forks workers on request. ``targets[i]()`` is what worker ``i`` runs; it returns an exit code."""

    def __init__(self, targets: list[Callable[[], int]], names: list[str], janitor: Callable[[], None] | None = None):
        self.targets = targets
        self.names = names
        self.janitor = janitor
        self.pid = -1
        self.sock: socket.socket | None = None

    # ---------------------------------------------------------------------- launcher side
    def start(self) -> None:
        if threading.active_count() > 1:
            raise ZygoteError(
                f"the zygote must be forked before any thread starts, but {threading.active_count()} threads run: "
                f"{[t.name for t in threading.enumerate()]}"
            )
        parent_sock, child_sock = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
        launcher = os.getpid()
        sys.stdout.flush()
        sys.stderr.flush()
        pid = os.fork()
        if pid == 0:  # zygote
            parent_sock.close()
            code = 0
            try:
                self._zygote_main(child_sock, launcher)
            except BaseException:
                code = 1
            finally:
                os._exit(code)
        child_sock.close()
        self.pid = pid
        self.sock = parent_sock
        self.sock.setblocking(True)

    def spawn(self, index: int) -> int:
        """Fork worker ``index``; returns its pid (soon a child of this process).

        Blocking but short (two forks, about a millisecond): the event loop never runs two
        spawns interleaved, so the request/reply channel needs no lock.
        """
        if self.sock is None:
            raise ZygoteError("zygote is not running")
        try:
            _send(self.sock, {"op": "spawn", "index": index})
            reply = _recv(self.sock)
        except (OSError, EOFError) as exc:
            raise ZygoteError(f"zygote (pid {self.pid}) is gone: {exc}") from exc
        if "error" in reply:
            raise ZygoteError(reply["error"])
        return int(reply["pid"])

    def stop(self) -> None:
        if self.sock is not None:
            try:
                _send(self.sock, {"op": "exit"})
            except OSError:
                pass
            self.sock.close()
            self.sock = None
        if self.pid > 0:
            try:
                os.waitpid(self.pid, 0)
            except ChildProcessError:
                pass
            self.pid = -1

    # ---------------------------------------------------------------------- zygote side
    def _zygote_main(self, sock: socket.socket, launcher: int) -> None:
        set_process_name("emos:zygote")
        os.setpgid(0, 0)  # Ctrl-C at the terminal is for the launcher, which stops us in order
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, lambda *_: self._orphaned())
        if not die_with(launcher):
            self._orphaned()
        while True:
            try:
                req = _recv(sock)
            except (EOFError, OSError):
                self._orphaned()
            if req.get("op") == "exit":
                os._exit(0)
            if req.get("op") == "spawn":
                try:
                    pid = self._double_fork(int(req["index"]), sock, launcher)
                    _send(sock, {"pid": pid})
                except Exception as exc:
                    _send(sock, {"error": f"{type(exc).__name__}: {exc}"})

    def _orphaned(self) -> None:
        """The launcher died without stopping us: clean its shared state, then leave."""
        time.sleep(0.3)  # workers got SIGTERM too; let them finish their last writes
        if self.janitor is not None:
            try:
                self.janitor()
            except Exception:
                pass
        os._exit(0)

    def _double_fork(self, index: int, sock: socket.socket, launcher: int) -> int:
        if not 0 <= index < len(self.targets):
            raise IndexError(f"no component #{index}")
        r, w = os.pipe()
        mid = os.fork()
        if mid == 0:  # intermediate
            os.close(r)
            worker = os.fork()
            if worker == 0:
                os.close(w)
                sock.close()
                self._worker_main(index, launcher)
            os.write(w, struct.pack("<i", worker))
            os._exit(0)
        os.close(w)
        data = b""
        while len(data) < 4:
            chunk = os.read(r, 4 - len(data))
            if not chunk:
                break
            data += chunk
        os.close(r)
        os.waitpid(mid, 0)
        if len(data) != 4:
            raise ZygoteError(f"fork of component #{index} failed")
        return struct.unpack("<i", data)[0]

    def _worker_main(self, index: int, launcher: int) -> None:
        code = 70
        try:
            set_process_name(f"emos:{self.names[index]}")
            for sig in (signal.SIGINT, signal.SIGTERM):
                signal.signal(sig, signal.SIG_DFL)
            # Wait to be re-parented to the launcher (the intermediate exits right away), then
            # ask to die with it.
            deadline = time.monotonic() + 2.0
            while os.getppid() != launcher and time.monotonic() < deadline:
                time.sleep(0.0002)
            if not die_with(launcher):
                os._exit(0)
            code = int(self.targets[index]() or 0)
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else 1
        except BaseException:
            import traceback

            traceback.print_exc()
            code = 70
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(code)


class ExitInfo:
    """How a process ended."""

    __slots__ = ("pid", "code", "signal", "at")

    def __init__(self, pid: int, code: int | None, sig: int | None, at: float):
        self.pid, self.code, self.signal, self.at = pid, code, sig, at

    @property
    def normal(self) -> bool:
        return self.code == 0

    def __str__(self) -> str:
        if self.signal is not None:
            return f"killed by {signal.Signals(self.signal).name}"
        return f"exited with code {self.code}"


class ProcessWatch:
    """Resolves a future with :class:`ExitInfo` the moment the process ends (pidfd in the event loop)."""

    def __init__(self, pid: int, loop: asyncio.AbstractEventLoop):
        self.pid = pid
        self.loop = loop
        self.exited: asyncio.Future[ExitInfo] = loop.create_future()
        self.pidfd = os.pidfd_open(pid)
        loop.add_reader(self.pidfd, self._on_ready)

    def _on_ready(self) -> None:
        at = time.monotonic()
        self.loop.remove_reader(self.pidfd)
        try:
            res = os.waitid(os.P_PIDFD, self.pidfd, os.WEXITED)
        except ChildProcessError:
            res = None  # not our child (should not happen with the subreaper); treat as vanished
        os.close(self.pidfd)
        self.pidfd = -1
        if res is None:
            info = ExitInfo(self.pid, None, None, at)
        elif res.si_code == os.CLD_EXITED:
            info = ExitInfo(self.pid, res.si_status, None, at)
        else:
            info = ExitInfo(self.pid, None, res.si_status, at)
        if not self.exited.done():
            self.exited.set_result(info)

    def send(self, sig: int) -> None:
        if self.pidfd >= 0:
            try:
                signal.pidfd_send_signal(self.pidfd, sig)
            except ProcessLookupError:
                pass

    def close(self) -> None:
        if self.pidfd >= 0:
            self.loop.remove_reader(self.pidfd)
            os.close(self.pidfd)
            self.pidfd = -1
