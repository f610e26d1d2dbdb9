"""``emos bench barn --jobs N``: trials side by side.

A trial is single-threaded: in-process, one simulator and one navigator on one core; through
the processes, a lock-step pipeline in which the simulator waits for its consumers, so one
world keeps about one core busy. On a machine with more cores than that, N trials at once
finish a 2500-trial run about N times sooner. The scores do not change: in-process the
navigator's compute time is charged in its thread's CPU time, not in wall time, and through the
processes the simulator advances only when the stack has answered each tick.

In-process trials run in worker processes (the interpreter lock would serialize threads);
each worker builds its navigator per trial, as a sequential run does. Trials through the
processes are already subprocesses: their referees run in threads of this process.
"""
from __future__ import annotations

import multiprocessing
import threading
from collections.abc import Callable
from concurrent.futures import Executor, Future, ProcessPoolExecutor, ThreadPoolExecutor
from pathlib import Path
from typing import Any

from .harness import BarnRules, EpisodeResult, run_episode


def in_process_trial(entry: Any, controller: str, rules: BarnRules, seed: int, png: Path | None) -> EpisodeResult:
    """One in-process trial, as the sequential loop runs it (a worker process's entry point)."""
    from .controllers import make_controller

    return run_episode(entry, make_controller(controller), rules, seed=seed, png_path=png)


class TrialPool:
    """Runs trials ``jobs`` at a time and hands each result to ``on_done`` as it finishes (the
    results file is written in finishing order, so an interruption loses only unfinished trials).
    ``jobs == 1`` runs each trial when it is asked for, in this thread."""

    def __init__(self, jobs: int, in_process: bool, on_done: Callable[[EpisodeResult], None]):
        if jobs < 1:
            raise ValueError(f"--jobs must be >= 1, got {jobs}")
        self.jobs = jobs
        self._on_done = on_done
        self._lock = threading.Lock()
        self._executor: Executor | None = None
        if jobs > 1:
            # forkserver: the workers do not inherit this process's threads or pybullet state
            self._executor = (ProcessPoolExecutor(jobs, mp_context=multiprocessing.get_context("forkserver"))
                              if in_process else ThreadPoolExecutor(jobs, thread_name_prefix="barn-trial"))

    def submit(self, fn: Callable[..., EpisodeResult], *args: Any) -> Callable[[], EpisodeResult]:
        """Start (or, with one job, defer) ``fn(*args)``; returns a call that waits for its result."""
        if self._executor is None:
            def run_now() -> EpisodeResult:
                result = fn(*args)
                self._done(result)
                return result

            return run_now
        future: Future = self._executor.submit(fn, *args)

        def record(f: Future) -> None:
            if not f.cancelled() and f.exception() is None:  # a cancelled or failed trial (a run being stopped) has none
                self._done(f.result())

        future.add_done_callback(record)
        return future.result

    def _done(self, result: EpisodeResult) -> None:
        with self._lock:
            self._on_done(result)

    def close(self, cancel: bool = False) -> None:
        if self._executor is not None:
            self._executor.shutdown(wait=True, cancel_futures=cancel)
