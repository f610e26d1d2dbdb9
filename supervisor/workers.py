"""Component incarnations as supervision-tree children, in a process or in a thread.

Starting one means: spawn it, wait for its hello on the supervisor socket, drive its lifecycle
to Inactive (and Active unless told otherwise) through its control socket, then watch it: death
through the pidfd (process) or the thread's end, hangs through missed status heartbeats.
"""
from __future__ import annotations

import asyncio
import logging
import os
import signal
import threading
import time
from typing import TYPE_CHECKING, Any

import psutil

from emos.core import control as C
from emos.core import lifecycle as L
from emos.core.component import BaseComponent
from emos.core.node import Node
from emos.core.rpc import AsyncRpcClient
from emos.supervisor.spawn import ExitInfo, ProcessWatch
from emos.supervisor.tree import Exit, StartFailed

if TYPE_CHECKING:
    from emos.supervisor.system import System

log = logging.getLogger("emos.supervisor")


class _Incarnation:
    """Shared bookkeeping of process and thread workers."""

    def __init__(self, system: System, index: int, component: BaseComponent, activate: bool):
        self.system = system
        self.index = index
        self.component = component
        self.name = component.component_name
        self.activate = activate
        self.exited: asyncio.Future[Exit] = asyncio.get_running_loop().create_future()
        self.pid: int | None = None
        self.started_at = time.monotonic()
        # Wall time, as status stamps are: a status stamped earlier is from a past incarnation.
        self.started_wall = time.time()
        self._stop_reason: str | None = None  # set when *we* end it: shutdown or hang

    async def _bring_up(self, died: asyncio.Future[Any]) -> None:
        self.system.heartbeats.expect(self.name, self.pid)
        hello = self.system.expect_hello(self.name, pid=self.pid)
        done, _ = await asyncio.wait({hello, died}, timeout=self.system.options.start_timeout, return_when=asyncio.FIRST_COMPLETED)
        if died in done:
            raise StartFailed(f"component {self.name!r} ended while starting: {died.result()}")
        if not done:
            raise StartFailed(f"component {self.name!r} did not report within {self.system.options.start_timeout:g} s")
        client = AsyncRpcClient(C.control_socket(self.system.ctx, self.name))
        try:
            target = L.LifecycleState.ACTIVE if self.activate else L.LifecycleState.INACTIVE
            for transition in L.path_to(L.LifecycleState.UNCONFIGURED, target):
                timeout = self.system.options.activate_timeout if transition == L.Transition.ACTIVATE else self.system.options.start_timeout
                call = asyncio.ensure_future(client.call(C.TRANSITION, transition=transition.value, timeout=timeout))
                done, _ = await asyncio.wait({call, died}, return_when=asyncio.FIRST_COMPLETED)
                if died in done:
                    call.cancel()
                    raise StartFailed(f"component {self.name!r} ended during {transition.value}: {died.result()}")
                call.result()
        finally:
            await client.close()
        self.system.heartbeats.watch(self.name, self)

    def info(self) -> dict[str, Any]:
        status = self.system.heartbeats.last_status(self.name)
        out: dict[str, Any] = {
            "name": self.name,
            "kind": "worker",
            "mode": self.mode,
            "pid": self.pid,
            "uptime_s": round(time.monotonic() - self.started_at, 3),
            "state": status.lifecycle_state if status else "starting",
            "health": _HEALTH_NAMES.get(status.status, str(status.status)) if status else "UNKNOWN",
        }
        if self.pid and self.mode == "process":
            try:
                proc = psutil.Process(self.pid)
                with proc.oneshot():
                    out["rss_mb"] = round(proc.memory_info().rss / 2**20, 1)
                    out["cpu_s"] = round(sum(proc.cpu_times()[:2]), 2)
            except psutil.Error:
                pass
        return out

    mode = "?"

    def on_hang(self, silent_for: float) -> None:
        raise NotImplementedError


_HEALTH_NAMES = {0: "HEALTHY", 1: "ALGORITHM_FAILURE", 2: "COMPONENT_FAILURE", 3: "SYSTEM_FAILURE", 4: "GENERAL"}


class ProcessWorker(_Incarnation):
    mode = "process"

    async def start(self) -> ProcessWorker:
        loop = asyncio.get_running_loop()
        self.pid = self.system.zygote.spawn(self.index)  # type: ignore[union-attr]
        self.system.reaper.worker_started(self.pid)
        self.watch = ProcessWatch(self.pid, loop, group=True)
        self.watch.exited.add_done_callback(self._on_exit)
        self.system.incarnation_started(self)
        try:
            await self._bring_up(self.watch.exited)
        except BaseException:
            self._stop_reason = "start_failed"
            self.watch.send(signal.SIGKILL)
            await asyncio.shield(self.watch.exited)
            raise
        return self

    def _on_exit(self, fut: asyncio.Future[ExitInfo]) -> None:
        info = fut.result()
        self.system.reaper.worker_ended(info.pid)
        self.system.heartbeats.unwatch(self.name, self)
        self.system.incarnation_ended(self)
        if self._stop_reason == "hang":
            result = Exit("hang", f"pid {info.pid} missed its heartbeat deadline; {info}", info.at)
        elif self._stop_reason is not None:
            result = Exit("shutdown", f"pid {info.pid} {info}", info.at)
        elif info.normal:
            result = Exit("normal", f"pid {info.pid} {info}", info.at)
        elif info.signal is not None:
            result = Exit("killed", f"pid {info.pid} {info}", info.at)
        else:
            result = Exit("crash", f"pid {info.pid} {info}", info.at)
        if not self.exited.done():
            self.exited.set_result(result)

    async def stop(self, timeout: float) -> Exit:
        if not self.exited.done():
            self._stop_reason = self._stop_reason or "shutdown"
            self.watch.send(signal.SIGTERM)
            try:
                await asyncio.wait_for(asyncio.shield(self.exited), timeout)
            except TimeoutError:
                log.warning("[%s] did not stop within %.1f s of SIGTERM: SIGKILL", self.name, timeout)
                self.watch.send(signal.SIGKILL)
        return await asyncio.shield(self.exited)

    def on_hang(self, silent_for: float) -> None:
        if self.exited.done() or self._stop_reason is not None:
            return
        log.error("[%s] no status for %.2f s (pid %s): killing it as hung", self.name, silent_for, self.pid)
        self._stop_reason = "hang"
        self.watch.send(signal.SIGKILL)


class ThreadWorker(_Incarnation):
    """Threaded mode: same lifecycle and supervision, but a hung thread cannot be killed, only abandoned."""

    mode = "thread"

    async def start(self) -> ThreadWorker:
        loop = asyncio.get_running_loop()
        self.pid = os.getpid()
        component = self.system.fresh_component(self.index)
        # No spinning for wake-ups in threads: a spinning thread holds the interpreter lock.
        self.node = Node(component, ctx=self.system.ctx, supervisor_socket=str(self.system.control_path), wake_spin_us=0)
        self._thread_done: asyncio.Future[Exit] = loop.create_future()

        def main() -> None:
            try:
                code = self.node.run(install_signal_handlers=False)
                result = Exit("normal" if code == 0 else "crash", f"thread ended with code {code}")
            except BaseException as exc:  # the component's thread died: that is its crash
                log.exception("[%s] thread crashed", self.name)
                result = Exit("crash", f"{type(exc).__name__}: {exc}")

            def finish() -> None:  # on the loop's thread: a future is not thread-safe
                if not self._thread_done.done():
                    self._thread_done.set_result(result)

            loop.call_soon_threadsafe(finish)

        self.thread = threading.Thread(target=main, name=f"emos:{self.name}", daemon=True)
        self.system.incarnation_started(self)
        self.thread.start()
        self._thread_done.add_done_callback(self._on_exit)
        try:
            await self._bring_up(self._thread_done)
        except BaseException:
            self._stop_reason = "start_failed"
            self.node.request_exit()
            raise
        return self

    def _on_exit(self, fut: asyncio.Future[Exit]) -> None:
        self.system.heartbeats.unwatch(self.name, self)
        self.system.incarnation_ended(self)
        result = fut.result()
        if self._stop_reason == "hang":
            result = Exit("hang", "thread missed its heartbeat deadline and was abandoned", result.at)
        elif self._stop_reason is not None:
            result = Exit("shutdown", result.detail, result.at)
        if not self.exited.done():
            self.exited.set_result(result)

    async def stop(self, timeout: float) -> Exit:
        if not self.exited.done():
            self._stop_reason = self._stop_reason or "shutdown"
            self.node.request_exit()
            try:
                await asyncio.wait_for(asyncio.shield(self.exited), timeout)
            except TimeoutError:
                log.error("[%s] thread did not stop within %.1f s; abandoning it", self.name, timeout)
                if not self._thread_done.done():
                    self._thread_done.set_result(Exit("shutdown", "abandoned after stop timeout"))
        return await asyncio.shield(self.exited)

    def on_hang(self, silent_for: float) -> None:
        if self.exited.done() or self._stop_reason is not None:
            return
        log.error("[%s] thread silent for %.2f s: abandoning it as hung (threads cannot be killed)", self.name, silent_for)
        self._stop_reason = "hang"
        self.node.request_exit()
        if not self._thread_done.done():
            self._thread_done.set_result(Exit("hang", "abandoned"))
