"""Finding the running system the CLI talks to."""
from __future__ import annotations

import argparse
import contextlib
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path

import psutil

from emos.core.discovery import printable
from emos.transport.context import RunContext


def add_run_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--run", default=None, metavar="RUN_ID",
                        help="run id of the system; may be left out when only one system is running (with several, the command lists them)")


def options_anywhere(group: argparse.ArgumentParser, verbs: Iterable[argparse.ArgumentParser],
                     add: Callable[[argparse.ArgumentParser], None]) -> None:
    """Give the options ``add`` defines to a verb group's parser and to each verb's, so that
    ``emos component --run X info NAME`` and ``emos component info --run X NAME`` mean the same.

    argparse copies everything a verb's parser holds over the group's namespace, defaults
    included, so in the verbs' copies the default is SUPPRESS: an option left out after the
    verb keeps the value (or the default) the group's parser gave it."""
    add(group)
    for verb in verbs:
        before = len(verb._actions)
        add(verb)
        for action in verb._actions[before:]:
            if action.help and "%(default)" in action.help:
                action.help = action.help.replace("%(default)s", str(action.default))
            action.default = argparse.SUPPRESS


def _describe_run(path: Path) -> str:
    """``RUN_ID (COMMAND, up N s)`` of a live run, for the lines that say which run is used.
    The run id starts with the launcher's pid; its command line is shown as printable text only."""
    run_id = path.name
    try:
        proc = psutil.Process(int(run_id.split("-", 1)[0]))
        words = proc.cmdline()
        up = time.time() - proc.create_time()
    except (ValueError, psutil.Error):
        return run_id
    if words and Path(words[0]).name.startswith("python"):
        words = words[2:] if words[1:2] == ["-m"] else words[1:]  # "emos run x.py", not "python3 -m emos run x.py"
    command = printable(" ".join(words), 4096)
    if len(command) > 80:
        command = command[:77] + "..."
    return f"{run_id} ({command or '?'}, up {up:.0f} s)"


def join_run(run_id: str | None) -> RunContext:
    """A non-owning context for a live run; exits with a clear message if there is none.

    Without ``--run`` the one live run is used, and a line on stderr says which; with more than
    one live run of this user the choice is ambiguous, and the command refuses, listing them
    (no run is "the newest" by accident: two recipes started together are both new)."""
    from emos.supervisor.system import find_runs
    from emos.transport.context import runtime_root

    runs = find_runs()
    if run_id:
        path = runtime_root() / run_id
        if path not in runs:
            sys.exit(f"emos: no running system with run id {run_id!r}; running: {[p.name for p in runs] or 'none'}")
    elif not runs:
        sys.exit("emos: no EMOS system is running for this user (start one with `emos run RECIPE.py`)")
    elif len(runs) > 1:
        listing = "\n".join(f"  {_describe_run(p)}" for p in runs)
        sys.exit(f"emos: {len(runs)} EMOS systems are running; say which one with --run RUN_ID:\n{listing}")
    else:
        path = runs[0]
        print(f"emos: using run {_describe_run(path)}", file=sys.stderr, flush=True)
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


_DEFERRED: list[int] = []  # signals that arrived inside signals_deferred(): delivered at its end
_DEFER_DEPTH = [0]


def hold_signal(signum: int) -> bool:
    """Inside signals_deferred(): keep ``signum`` for the end of the block and return True (the
    SIGTERM handler then returns instead of raising); outside, False."""
    if _DEFER_DEPTH[0] > 0:
        _DEFERRED.append(signum)
        return True
    return False


@contextlib.contextmanager
def signals_deferred() -> Iterator[None]:
    """Hold SIGINT and SIGTERM while resources are being created or released, so a Ctrl-C or
    SIGTERM never lands half way (a ring made but not yet known to the code that removes it);
    a signal that arrived meanwhile is delivered on exit from the block.

    Blocking the signals in this thread is not enough: the kernel gives a process signal to any
    thread that does not block it (a library's helper thread), and Python then runs the handler
    in the main thread at once. So the handlers also note a signal and return while inside."""
    held = {signal.SIGINT, signal.SIGTERM}
    before = signal.pthread_sigmask(signal.SIG_BLOCK, held)
    outermost = _DEFER_DEPTH[0] == 0
    previous_int = None
    if outermost and threading.current_thread() is threading.main_thread():
        previous_int = signal.signal(signal.SIGINT, lambda signum, frame: _DEFERRED.append(signum))
    _DEFER_DEPTH[0] += 1
    try:
        yield
    finally:
        _DEFER_DEPTH[0] -= 1
        if previous_int is not None:
            signal.signal(signal.SIGINT, previous_int)
        signal.pthread_sigmask(signal.SIG_SETMASK, before)
        if outermost and _DEFERRED:
            signum = _DEFERRED[0]
            _DEFERRED.clear()
            if signum == signal.SIGINT:
                raise KeyboardInterrupt
            raise SystemExit(128 + signum)
