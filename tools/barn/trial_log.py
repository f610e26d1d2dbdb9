"""``emos bench barn --results FILE``: every finished trial appended to a JSON-lines file, so a
long run (250 worlds x 10 seeds through the processes is hours) survives an interruption and
resumes where it stopped.

The first line names the configuration (controller, robot, rules, mode, world source); a file
written under another configuration is refused rather than mixed into this run's numbers. Each
further line is one trial; a trial already in the file (same world and seed) is not run again.
A line cut short by a crash mid-write is skipped with a warning: only that trial runs again.
"""
from __future__ import annotations

import json
import os
import sys
from pathlib import Path
from typing import Any

import attrs

from emos.errors import EmosError

from .harness import EpisodeResult


class TrialLogError(EmosError, ValueError):
    """The results file cannot be used for this run (another configuration, not ours, unreadable)."""


class TrialLog:
    def __init__(self, path: Path, config: dict[str, Any]):
        self.path = Path(path)
        self.config = config
        self.trials: dict[tuple[int, int], EpisodeResult] = {}
        if self.path.exists() and self.path.stat().st_size > 0:
            self._load()
        else:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._write({"config": config})

    def _load(self) -> None:
        head, trials = read_results(self.path, "that trial runs again")
        if head != self.config:
            diff = {k: (head.get(k), v) for k, v in self.config.items() if head.get(k) != v}
            raise TrialLogError(f"{self.path} holds trials of another configuration "
                                f"({', '.join(f'{k}: {a!r} there, {b!r} now' for k, (a, b) in diff.items()) or 'different keys'}); "
                                "give another --results file")
        for result in trials:
            self.trials[(result.idx, result.seed)] = result

    def get(self, idx: int, seed: int) -> EpisodeResult | None:
        return self.trials.get((idx, seed))

    def append(self, result: EpisodeResult) -> None:
        self.trials[(result.idx, result.seed)] = result
        self._write({"trial": attrs.asdict(result)})

    def _write(self, record: dict) -> None:
        # One line per write, flushed to disk: a kill loses at most the trial being written.
        with open(self.path, "a", encoding="utf-8") as f:
            f.write(json.dumps(record) + "\n")
            f.flush()
            os.fsync(f.fileno())


def read_results(path: Path, unreadable: str = "skipped") -> tuple[dict[str, Any], list[EpisodeResult]]:
    """(configuration, trials) of a results file; an unreadable trial line is reported on stderr
    with ``unreadable`` (what happens to it) and left out; a later line of the same world and
    seed replaces an earlier one."""
    path = Path(path)
    try:
        with open(path, encoding="utf-8") as f:
            lines = f.read().splitlines()
    except OSError as exc:
        raise TrialLogError(f"{path}: cannot read the results file ({exc.strerror or exc})") from None
    try:
        head = json.loads(lines[0])["config"]
        if not isinstance(head, dict):
            raise TypeError
    except (ValueError, KeyError, TypeError, IndexError):
        raise TrialLogError(f"{path}: not a results file of emos bench barn (no configuration line)") from None
    fields = {f.name for f in attrs.fields(EpisodeResult)}
    trials: dict[tuple[int, int], EpisodeResult] = {}
    for n, line in enumerate(lines[1:], 2):
        try:
            row = json.loads(line)["trial"]
            result = EpisodeResult(**{k: v for k, v in row.items() if k in fields})
            key = (int(result.idx), int(result.seed))
        except (ValueError, KeyError, TypeError) as exc:
            print(f"emos bench barn: {path} line {n} unreadable ({type(exc).__name__}: {str(exc)[:160]}); {unreadable}", file=sys.stderr)
            continue
        trials[key] = result
    return head, list(trials.values())
