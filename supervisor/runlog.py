"""Each ``emos run`` keeps its output: ``~/emos/logs/<recipe>_<YYYYmmdd-HHMMSS>.log``.

The run's stdout and stderr (and so those of every component process it starts, which inherit
them) go through a ``tee`` each: the terminal sees what it always saw, and the file gets a copy.
The tees run in their own session and ignore SIGINT, so Ctrl-C on the terminal reaches the
supervisor (which still has things to say while it stops) and not them; they end when the last
process writing to them has exited. The oldest logs beyond ``KEEP`` are removed.
"""
from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

from emos.supervisor.recipes import logs_dir

KEEP = 100


def recipe_log_name(recipe: Path) -> str:
    stem = recipe.parent.name if recipe.name == "recipe.py" else recipe.stem
    return "".join(ch if ch.isalnum() or ch in "-_." else "_" for ch in stem)


def list_logs() -> list[Path]:
    folder = logs_dir()
    if not folder.is_dir():
        return []
    dated = []
    for path in folder.glob("*.log"):
        try:
            dated.append((path.stat().st_mtime, path))
        except FileNotFoundError:  # pruned by another run starting at the same moment
            continue
    return [path for _, path in sorted(dated)]


def _prune(keep: int) -> None:
    logs = list_logs()
    for old in logs[: max(0, len(logs) - keep)]:
        try:
            old.unlink()
        except OSError:
            pass


def start_run_log(recipe: Path, argv: list[str]) -> Path | None:
    """Copy this process's stdout and stderr into a new log file; returns its path (None if it
    cannot: the run goes on without a log, and says why)."""
    folder = logs_dir()
    try:
        folder.mkdir(parents=True, exist_ok=True, mode=0o700)
        base = f"{recipe_log_name(recipe)}_{time.strftime('%Y%m%d-%H%M%S')}"
        for n in range(1, 1000):  # runs of one recipe started in the same second (in parallel, too)
            path = folder / (f"{base}.log" if n == 1 else f"{base}~{n}.log")
            try:
                with open(path, "x") as f:  # "x": a name another run took meanwhile is skipped
                    f.write(f"# emos run {' '.join(argv)}\n# recipe {recipe.resolve()}  pid {os.getpid()}  started {time.strftime('%Y-%m-%d %H:%M:%S')}\n")
            except FileExistsError:
                continue
            break
        else:
            raise FileExistsError(f"{folder}: 999 logs named {base}*")
        os.chmod(path, 0o600)
    except OSError as exc:
        print(f"emos run: not keeping a log of this run ({exc})", file=sys.stderr)
        return None
    sys.stdout.flush()
    sys.stderr.flush()
    for fd in (1, 2):
        read_end, write_end = os.pipe()
        try:
            subprocess.Popen(["tee", "-a", "-i", str(path)], stdin=read_end, stdout=fd, stderr=subprocess.DEVNULL,
                             start_new_session=True, close_fds=True)
        except OSError as exc:
            os.close(read_end)
            os.close(write_end)
            print(f"emos run: not keeping a log of this run (tee: {exc})", file=sys.stderr)
            return None
        os.close(read_end)
        os.dup2(write_end, fd)
        os.close(write_end)
    _prune(KEEP)
    return path
