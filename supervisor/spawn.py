"""Starting component processes fast and safely, and learning of their death at once.

* **Zygote.** At bring-up, before the launcher starts any thread or event loop, it forks a
  *zygote*: a single-threaded copy of the recipe process holding every component object as the
  recipe built it. Each (re)start asks the zygote to fork. No re-import of the recipe (so
  recipes need no ``__main__`` guard and may define callables anywhere), no pickling of
  components, and no fork of a process that runs threads.
* **Double fork + subreaper.** The zygote forks an intermediate that forks the worker and exits
  at once. The launcher has marked itself ``PR_SET_CHILD_SUBREAPER``, so the orphaned worker is
  re-parented to the launcher, which alone reaps it and reads its exit status. Each worker
  marks itself a subreaper too (the flag is not inherited, and the zygote must not have it),
  so what its descendants orphan stays below it (reaper.py).
* **pidfd.** The launcher watches a ``pidfd`` of every worker in its event loop: death is
  known the moment the kernel reaps the task, with no polling.
* **Parent death.** Workers and the zygote set ``PR_SET_PDEATHSIG`` to the launcher: if the
  launcher is SIGKILLed they get SIGTERM, and the zygote then removes the run's shared memory.
"""
from __future__ import annotations

import asyncio
import functools
import logging
import os
import select
import signal
import socket
import struct
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

import msgpack

# The prctl helpers live in core (the Zenoh status bridge below the supervisor needs them too);
# re-exported here for the zygote, the workers and existing callers.
from emos.core.prctl import PR_SET_CHILD_SUBREAPER, PR_SET_NAME, PR_SET_PDEATHSIG, become_subreaper, die_with, prctl, set_process_name  # noqa: F401
from emos.errors import EmosError
from emos.supervisor.reaper import ENV_WORKER_PID, AdoptedReaper, end_descendants, kill_group, kill_worker_trees, proc_stat

log = logging.getLogger("emos.supervisor")

_LEN = struct.Struct("<I")


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


def _await_parent(pid: int, timeout: float = 2.0) -> None:
    deadline = time.monotonic() + timeout
    while os.getppid() != pid and time.monotonic() < deadline:
        time.sleep(0.0002)


class ZygoteError(EmosError, RuntimeError):
    pass


SPAWN_TIMEOUT_S = 2.0  # a healthy zygote answers in milliseconds; a stopped one never does
# A zygote that is runnable but starved (a load of 50 on 2 cores, a niced run) can take seconds
# to answer: it is given up only when it is stopped or gone, or after this long without an answer.
ZYGOTE_HANG_S = 30.0


def _stopped_or_gone(pid: int) -> bool:
    stat = proc_stat(pid)
    return stat is None or stat.state in ("T", "t", "Z", "X")


class _ZygoteHandle:
    """The launcher's end of one zygote process."""

    def __init__(self, pid: int, sock: socket.socket, direct_child: bool):
        self.pid, self.sock, self.direct_child = pid, sock, direct_child
        sock.settimeout(SPAWN_TIMEOUT_S)

    def request(self, req: dict, with_fd: bool = False) -> tuple[dict, int | None]:
        _send(self.sock, req)
        self._await_reply()
        if not with_fd:
            return _recv(self.sock), None
        msg, fds, _, _ = socket.recv_fds(self.sock, 4, 1)
        if len(msg) < 4:
            raise EOFError("zygote channel closed")
        (n,) = _LEN.unpack(msg)
        body = b""
        while len(body) < n:
            chunk = self.sock.recv(n - len(body))
            if not chunk:
                raise EOFError("zygote channel closed")
            body += chunk
        return msgpack.unpackb(body, raw=False), (fds[0] if fds else None)

    def _await_reply(self) -> None:
        """Return once the zygote's reply is arriving; TimeoutError (naming why) if the zygote is
        stopped or gone after SPAWN_TIMEOUT_S, or runs without answering for ZYGOTE_HANG_S."""
        waited = 0.0
        while not select.select([self.sock], [], [], SPAWN_TIMEOUT_S)[0]:
            waited += SPAWN_TIMEOUT_S
            if _stopped_or_gone(self.pid):
                raise TimeoutError(f"did not answer within {waited:g} s and is stopped or gone")
            if waited >= ZYGOTE_HANG_S:
                raise TimeoutError(f"did not answer within {waited:g} s although it runs (hung)")
            log.warning("zygote %d has not answered for %g s; it runs (a starved machine?), waiting", self.pid, waited)

    def discard(self) -> None:
        """Kill and reap a zygote that failed us."""
        try:
            os.kill(self.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        self.close_and_reap()

    def close_and_reap(self) -> None:
        self.sock.close()
        try:
            os.waitpid(self.pid, 0)
        except ChildProcessError:
            pass  # already reaped


class Zygote:
    """Forks workers on request. ``targets[i]()`` is what worker ``i`` runs; it returns an exit code.

    Two zygotes run: the primary forks workers; the spare stands by. If the primary dies or
    stops answering, the spare takes over and is asked to clone itself into a new spare. A
    zygote clones by double fork (the clone is re-parented to the launcher, like workers) and
    hands the launcher its end of the new channel over ``SCM_RIGHTS``. The launcher itself never
    forks again after start-up, so no process with an event loop or threads is ever forked.
    """

    def __init__(self, targets: list[Callable[[], int]], names: list[str], janitor: Callable[[], None] | None = None):
        self.targets = targets
        self.names = names
        self.janitor = janitor
        self.primary: _ZygoteHandle | None = None
        self.spare: _ZygoteHandle | None = None
        self.replacements = 0
        self._latest: dict[int, int] = {}  # zygote side: index -> pid of the worker it forked last

    @property
    def pid(self) -> int:
        return self.primary.pid if self.primary else -1

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
            self._run_zygote(child_sock, launcher)
        child_sock.close()
        self.primary = _ZygoteHandle(pid, parent_sock, direct_child=True)
        self.spare = self._clone(self.primary)

    def _clone(self, source: _ZygoteHandle) -> _ZygoteHandle | None:
        try:
            reply, fd = source.request({"op": "clone"}, with_fd=True)
        except (OSError, EOFError) as exc:
            log.error("zygote %d could not clone a spare: %s", source.pid, exc)
            return None
        if "error" in reply or fd is None:
            log.error("zygote %d could not clone a spare: %s", source.pid, reply.get("error"))
            return None
        return _ZygoteHandle(int(reply["pid"]), socket.socket(fileno=fd), direct_child=False)

    def _replace_primary(self, why: str) -> None:
        failed = self.primary
        log.error("zygote %s %s; switching to the spare", failed.pid if failed else "?", why)
        if failed is not None:
            failed.discard()
        self.primary, self.spare = self.spare, None
        self.replacements += 1
        if self.primary is not None:
            self.spare = self._clone(self.primary)

    def replace_dead(self) -> None:
        """Notice a zygote that died between spawns (the launcher's sweep calls this): reap it
        now, so it is no zombie until the next restart, and have a spare ready again."""
        for handle in (self.primary, self.spare):
            if handle is None:
                continue
            try:
                done, _ = os.waitpid(handle.pid, os.WNOHANG)
            except ChildProcessError:
                # Not our child: reaped already (gone), or a clone not adopted yet (it is its
                # intermediate's child for a moment after birth, longer on a loaded machine).
                # Taking the latter for dead dropped a live spare, which then exited on its
                # closed channel as a zombie nobody knew to reap (chaos sensor-kills, loaded).
                done = handle.pid if proc_stat(handle.pid) is None else 0
            if not done:
                continue
            if handle is self.primary:
                self._replace_primary("died")  # discard() finds it already reaped
            else:
                log.error("spare zygote %d died; cloning a new one", handle.pid)
                handle.sock.close()
                self.spare = self._clone(self.primary) if self.primary is not None else None

    def spawn(self, index: int) -> int:
        """Fork worker ``index``; returns its pid (soon a child of this process).

        Blocking but short (two forks, about a millisecond): the event loop never runs two
        spawns interleaved, so the request/reply channel needs no lock.
        """
        for _ in range(2):
            if self.primary is None:
                break
            try:
                reply, _ = self.primary.request({"op": "spawn", "index": index})
            except TimeoutError as exc:
                self._replace_primary(str(exc))
                continue
            except (OSError, EOFError) as exc:
                self._replace_primary(f"is gone ({exc})")
                continue
            if "error" in reply:
                raise ZygoteError(reply["error"])
            return int(reply["pid"])
        raise ZygoteError("no zygote left to fork components (primary and spare both failed)")

    def stop(self) -> None:
        for handle in (self.spare, self.primary):
            if handle is None:
                continue
            try:
                _send(handle.sock, {"op": "exit"})
            except OSError:
                pass
            handle.close_and_reap()
        self.primary = self.spare = None

    # ---------------------------------------------------------------------- zygote side
    def _run_zygote(self, sock: socket.socket, launcher: int) -> None:
        code = 0
        try:
            self._zygote_main(sock, launcher)
        except BaseException:
            code = 1
        finally:
            os._exit(code)

    def _zygote_main(self, sock: socket.socket, launcher: int) -> None:
        set_process_name("emos:zygote")
        if os.getpgid(0) != os.getpid():
            os.setpgid(0, 0)  # Ctrl-C at the terminal is for the launcher, which stops us in order
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, lambda *_: self._orphaned())
        signal.signal(signal.SIGCHLD, signal.SIG_DFL)
        _await_parent(launcher)  # a cloned spare is adopted by the launcher a moment after birth
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
                    index = int(req["index"])
                    pid = self._double_fork(functools.partial(self._worker_main, index, launcher), sock)
                    self._latest[index] = pid
                    _send(sock, {"pid": pid})
                except Exception as exc:
                    _send(sock, {"error": f"{type(exc).__name__}: {exc}"})
            elif req.get("op") == "clone":
                mine, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)

                def clone_main(mine: socket.socket = mine, theirs: socket.socket = theirs) -> None:
                    mine.close()  # the launcher's end: the clone keeps only its own
                    self._run_zygote(theirs, launcher)

                try:
                    pid = self._double_fork(clone_main, sock)
                    body = msgpack.packb({"pid": pid})
                    # The launcher's end of the clone's channel travels with the reply.
                    socket.send_fds(sock, [_LEN.pack(len(body)) + body], [mine.fileno()])
                except Exception as exc:
                    _send(sock, {"error": f"{type(exc).__name__}: {exc}"})
                finally:
                    mine.close()
                    theirs.close()

    def _orphaned(self) -> None:
        """The launcher died without stopping us: clean its shared state, then leave."""
        time.sleep(0.3)  # workers got SIGTERM too; let them finish their last writes
        # Their children did not: end each worker's process group (see reaper.py). Only the
        # latest incarnations: the launcher killed the groups of earlier ones when they died.
        try:
            kill_worker_trees(self._latest.values())
        except Exception:
            pass
        if self.janitor is not None:
            try:
                self.janitor()
            except Exception:
                pass
        os._exit(0)

    def _double_fork(self, child: Callable[[], Any], sock: socket.socket) -> int:
        """Run ``child`` in a grandchild that the launcher (subreaper) will adopt; its pid."""
        r, w = os.pipe()
        mid = os.fork()
        if mid == 0:  # intermediate
            os.close(r)
            worker = os.fork()
            if worker == 0:
                os.close(w)
                sock.close()
                child()
                os._exit(0)
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
            raise ZygoteError("fork failed")
        return struct.unpack("<i", data)[0]

    def _worker_main(self, index: int, launcher: int) -> None:
        code = 70
        if not 0 <= index < len(self.targets):
            os._exit(code)
        me = os.getpid()
        try:
            set_process_name(f"emos:{self.names[index]}")
            # A session (and process group) of our own, and the subreaper of everything below
            # us: orphans of our descendants (daemons that left the session) come back to us,
            # not to the launcher, and we end them when we end (see reaper.py).
            os.setsid()
            try:
                become_subreaper()
            except OSError as exc:
                log.warning("[%s] cannot become a child subreaper (%s): daemons it starts are ended by the launcher", self.names[index], exc)
            AdoptedReaper().start()
            os.environ[ENV_WORKER_PID] = str(me)
            for sig in (signal.SIGINT, signal.SIGTERM):
                signal.signal(sig, signal.SIG_DFL)
            # Wait to be re-parented to the launcher (the intermediate exits right away), then
            # ask to die with it.
            _await_parent(launcher)
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
            if os.getpid() == me:  # not in a child the component forked and that unwound to here
                try:
                    end_descendants()
                except Exception:
                    pass
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

    def __init__(self, pid: int, loop: asyncio.AbstractEventLoop, group: bool = False):
        """``group``: the process leads its own process group, which is SIGKILLed when it ends
        (before it is reaped, so the group id cannot have been reused)."""
        self.pid = pid
        self.group = group
        self.loop = loop
        self.exited: asyncio.Future[ExitInfo] = loop.create_future()
        self.pidfd = os.pidfd_open(pid)
        loop.add_reader(self.pidfd, self._on_ready)

    def _on_ready(self) -> None:
        at = time.monotonic()
        self.loop.remove_reader(self.pidfd)
        if self.group:
            kill_group(self.pid, signal.SIGKILL)
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
        """Signal the process, and its whole group if it leads one; nothing once it is reaped."""
        if self.pidfd >= 0:
            try:
                signal.pidfd_send_signal(self.pidfd, sig)
            except ProcessLookupError:
                pass
            if self.group:
                kill_group(self.pid, sig)

    def close(self) -> None:
        if self.pidfd >= 0:
            self.loop.remove_reader(self.pidfd)
            os.close(self.pidfd)
            self.pidfd = -1
