"""Finding the running system the CLI talks to."""
from __future__ import annotations

import argparse
import contextlib
import signal
import sys
from collections.abc import Iterator
from pathlib import Path

from emos.transport.context import RunContext


def add_run_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--run", help="run id of the system (default: the newest running one)")


def join_run(run_id: str | None) -> RunContext:
    """A non-owning context for a live run; exits with a clear message if there is none."""
    from emos.supervisor.system import find_runs
    from emos.transport.context import runtime_root

    runs = find_runs()
    if run_id:
        path = runtime_root() / run_id
        if path not in runs:
            sys.exit(f"emos: no running system with run id {run_id!r}; running: {[p.name for p in runs] or 'none'}")
    elif not runs:
        sys.exit("emos: no EMOS system is running for this user (start one with `emos run RECIPE.py`)")
    else:
        path = runs[0]
    return RunContext(path.name, Path(path), owner=False)


_TERMINATED: list[int] = []  # the signal numbers that asked this command to end


def note_termination(signum: int) -> None:
    """Remember that ``signum`` asked the command to end (the SIGTERM handler calls it)."""
    _TERMINATED.append(signum)


def exit_if_terminated() -> None:
    """Raise the SystemExit a SIGTERM asked for, if it has not ended the command yet.

    The handler raises SystemExit where the main thread happens to be; if that is inside a
    ``__del__`` or a weakref or GC callback, Python prints "Exception ignored" and goes on, and
    a command that loops until it is told to stop would loop forever (a SIGTERMed ``emos topic
    echo`` did, for 23 minutes). Loops that run until a signal call this on every turn."""
    if _TERMINATED:
        raise SystemExit(128 + _TERMINATED[0])


@contextlib.contextmanager
def signals_deferred() -> Iterator[None]:
    """Hold SIGINT and SIGTERM while resources are being created or released, so a Ctrl-C or
    SIGTERM never lands half way (a FIFO made but not yet known to the code that removes it);
    a signal that arrived meanwhile is delivered on exit from the block."""
    held = {signal.SIGINT, signal.SIGTERM}
    before = signal.pthread_sigmask(signal.SIG_BLOCK, held)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, before)
