"""``emos bench barn --report FILE``: what a results file (``--results``) holds so far, without
running anything: its configuration, how many worlds have all their seeds, the official rates
over every trial and over the tuning and report splits (``idx % 5 != 0`` / ``== 0``), and each
failure with its reason. A long run can be read while it goes on, or after it was stopped."""
from __future__ import annotations

import json
import sys
from collections import Counter
from pathlib import Path
from typing import Any

from .harness import EpisodeResult
from .trial_log import TrialLogError, read_results

SPLITS = (("all", lambda idx: True), ("tune", lambda idx: idx % 5 != 0), ("test", lambda idx: idx % 5 == 0))
# The official rates, as both the report's and the comparison's tables show them.
RATE_COLUMNS = [("success_rate", "success", ".3f"), ("collision_rate", "collision", ".3f"),
                ("timeout_rate", "timeout", ".3f"), ("mean_metric", "metric (2 OT)", ".4f")]


def build_report(path: Path, trials: list[EpisodeResult] | None = None) -> dict[str, Any]:
    """The report of a results file, or of ``trials`` (a subset of its trials) when given."""
    from . import summarize

    config, everything = read_results(path)
    if trials is None:
        trials = everything
    per_world = Counter(t.idx for t in trials)
    seeds = max(per_world.values(), default=0)
    splits = {}
    for name, keep in SPLITS:
        chosen = [t for t in trials if keep(t.idx)]
        splits[name] = {"trials": len(chosen), "worlds": len({t.idx for t in chosen}),
                        **(summarize(chosen) if chosen else {})}
    failures = sorted((t for t in trials if not t.success), key=lambda t: (t.idx, t.seed))
    return {
        "config": config, "trials": len(trials), "worlds": len(per_world), "seeds": seeds,
        "complete_worlds": sum(1 for n in per_world.values() if n == seeds),
        "splits": splits,
        "failures": [{"idx": t.idx, "seed": t.seed, "reason": t.reason or _kind(t)} for t in failures],
    }


def build_comparison(path: Path, other: Path) -> dict[str, Any]:
    """Both files' reports over the world-seed pairs both hold, and per world the outcomes that
    differ: the same trials (seeds are drawn per world and seed base) on two versions of a
    navigator, or two configurations."""
    (mine_config, mine), (their_config, theirs) = read_results(path), read_results(other)
    a, b = paired_trials(mine, theirs)
    changed: dict[int, dict[str, int]] = {}
    for x, y in zip(a, b):
        if x.success != y.success:
            row = changed.setdefault(x.idx, {"fixed": 0, "broken": 0})
            row["fixed" if x.success else "broken"] += 1
    differ = sorted(k for k in set(mine_config) | set(their_config) if mine_config.get(k) != their_config.get(k))
    return {"pairs": len(a), "report": build_report(path, a), "against": build_report(other, b),
            "config_differs_in": differ, "changed_worlds": [{"idx": idx, **row} for idx, row in sorted(changed.items())]}


def paired_trials(mine: list[EpisodeResult], theirs: list[EpisodeResult]) -> tuple[list[EpisodeResult], list[EpisodeResult]]:
    """The trials of each list whose world-seed pair the other holds too, in the same order."""
    key = lambda t: (t.idx, t.seed)  # noqa: E731
    common = {key(t) for t in mine} & {key(t) for t in theirs}
    return (sorted((t for t in mine if key(t) in common), key=key),
            sorted((t for t in theirs if key(t) in common), key=key))


def _built(build: Any, *paths: Path) -> dict[str, Any] | None:
    """``build(*paths)``, or None after saying on stderr why the files cannot be read."""
    try:
        return build(*paths)
    except TrialLogError as exc:
        print(f"emos bench barn: {exc}", file=sys.stderr)
        return None


def run_comparison(path: Path, other: Path, as_json: bool, plot: Path | None = None) -> int:
    comparison = _built(build_comparison, path, other)
    if comparison is None:
        return 2
    if plot is not None and comparison["pairs"]:
        mine, theirs = paired_trials(read_results(path)[1], read_results(other)[1])
        _plot(plot, [(str(path), mine), (str(other), theirs)])
    if as_json:
        print(json.dumps(comparison))
        return 0
    if not comparison["pairs"]:
        print(f"{path} and {other} share no world-seed pair yet")
        return 0
    from emos.tools.bench.common import table

    differ = comparison["config_differs_in"]
    print(f"{comparison['pairs']} world-seed pairs in both files"
          + (f"; their configurations differ in: {', '.join(differ)}" if differ else " (same configuration)"))
    rows = [{"file": name, "split": split, **report["splits"][split]}
            for split in ("all", "tune", "test") for name, report in ((str(path), comparison["report"]), (str(other), comparison["against"]))
            if report["splits"][split]["trials"]]
    print(table(rows, [("split", "split", "s"), ("file", "file", "s"), ("trials", "trials", "d"), *RATE_COLUMNS,
                       ("mean_time_s", "time s", ".2f")]))
    mine_name, their_name = (path.name, other.name) if path.name != other.name else (str(path), str(other))
    for row in comparison["changed_worlds"]:
        print(f"  world {row['idx']}: {row['fixed']} seed(s) succeed only in {mine_name}, {row['broken']} only in {their_name}")
    return 0


def _plot(plot: Path, panels: list[tuple[str, list[EpisodeResult]]]) -> None:
    from .report_plot import save_outcome_map

    save_outcome_map(plot, panels)
    print(f"emos bench barn: outcome map written to {plot}", file=sys.stderr)  # stdout stays the report (or its JSON)


def _kind(t: EpisodeResult) -> str:
    return "collision" if t.collided else ("time limit" if t.timeout else "failed")


def run_report(path: Path, as_json: bool, plot: Path | None = None) -> int:
    report = _built(build_report, path)
    if report is None:
        return 2
    if plot is not None and report["trials"]:
        _plot(plot, [(str(path), read_results(path)[1])])
    if as_json:
        print(json.dumps(report))
        return 0
    from emos.tools.bench.common import table

    cfg = report["config"]
    if not report["trials"]:
        print(f"{path}: no finished trial yet, controller {cfg.get('controller', '?')}")
        return 0
    seeds = f"all {report['seeds']} seeds" if report["seeds"] > 1 else "its seed"
    print(f"{path}: {report['trials']} trials, {report['worlds']} worlds ({report['complete_worlds']} with {seeds}), "
          f"controller {cfg.get('controller', '?')}")
    rows = [{"split": name, **split} for name, split in report["splits"].items() if split["trials"]]
    print(table(rows, [("split", "split", "s"), ("worlds", "worlds", "d"), ("trials", "trials", "d"), *RATE_COLUMNS,
                       ("metric_4t", "metric (4 OT)", ".4f"), ("deadline_misses", "deadline misses", ".0f"),
                       ("mean_time_s", "time s", ".2f")]))
    for f in report["failures"]:
        print(f"  world {f['idx']} seed {f['seed']}: {f['reason']}")
    return 0
