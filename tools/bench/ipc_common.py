"""Pieces the ``emos bench ipc`` methods share: payloads, the helper processes, topic clean-up."""
from __future__ import annotations

import multiprocessing as mp
import os
import signal
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from multiprocessing.process import BaseProcess
from typing import Any

import numpy as np

from emos.core.prctl import die_with, set_process_name
from emos.transport.context import SHM_DIR, RunContext

# Fork, not spawn: the helper starts in milliseconds and inherits the run context (EMOS topics
# are only visible inside one run). The benchmark forks only while it runs no threads of its own
# (every multiprocessing.Queue is closed and its feeder thread joined before the next fork).
FORK = mp.get_context("fork")

# ``(benchmark CPU, helper CPU)`` or None: where the two ends run (``--cpus``). Latency benchmarks
# pin both ends, each to its own CPU, so that scheduler placement (which CPU a woken process
# lands on, with which caches) does not decide the result; see docs/benchmarks.md.
PLACEMENT: tuple[int, int] | None = None


@contextmanager
def placed() -> Iterator[None]:
    """Run the benchmark's own end on its CPU (if pinning), and restore its affinity after."""
    if PLACEMENT is None:
        yield
        return
    before = os.sched_getaffinity(0)
    os.sched_setaffinity(0, {PLACEMENT[0]})
    try:
        yield
    finally:
        os.sched_setaffinity(0, before)


def random_payload(size: int) -> np.ndarray:
    """``size`` random bytes: incompressible, and an echo that mangles them is caught."""
    return np.random.default_rng(size).integers(0, 256, size, dtype=np.uint8)


def _child_main(parent_pid: int, name: str, target: Callable[..., None], args: tuple) -> None:
    set_process_name(name)
    # Ctrl-C at the terminal reaches the whole foreground group: the benchmark handles it and
    # stops its helpers in order, so they ignore it rather than each print a traceback.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # If the benchmark dies (Ctrl-C, SIGKILL), its helper must not linger.
    if not die_with(parent_pid, signal.SIGTERM):
        os._exit(1)
    if PLACEMENT is not None:
        os.sched_setaffinity(0, {PLACEMENT[1]})
    target(*args)


def start_child(target: Callable[..., None], args: tuple, name: str) -> BaseProcess:
    """Fork a helper process running ``target(*args)``; it dies with this process."""
    proc = FORK.Process(target=_child_main, args=(os.getpid(), name, target, args), daemon=True)
    proc.start()
    return proc


def stop_child(proc: BaseProcess, timeout: float = 10.0) -> int | None:
    """Wait for a helper asked to stop; terminate, then kill, one that does not. Returns its exit code."""
    proc.join(timeout)
    if proc.is_alive():
        proc.terminate()
        proc.join(5.0)
    if proc.is_alive():
        proc.kill()
        proc.join()
    return proc.exitcode


def wait_ready(conn: Any, proc: BaseProcess, timeout: float = 30.0) -> None:
    """Block until the helper reports ready on ``conn``; a clear error if it died or hung."""
    if not conn.poll(timeout):
        raise RuntimeError(f"benchmark helper {proc.name} not ready after {timeout:.0f} s (exit code {proc.exitcode})")
    try:
        conn.recv()
    except EOFError:
        raise RuntimeError(f"benchmark helper {proc.name} died while starting (exit code {proc.exitcode})") from None


def remove_topic(ctx: RunContext, topic: str) -> None:
    """Unlink the rings of a finished measurement now, not at exit: at 8 MiB a ring of 16 slots
    holds over 130 MB of /dev/shm, and every size and method has its own topics."""
    for name in ctx.topic_segments(topic):
        try:
            os.unlink(SHM_DIR / name)
        except FileNotFoundError:
            pass
