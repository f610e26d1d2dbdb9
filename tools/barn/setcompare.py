"""Two BARN result files of different world sets side by side (a generated set against the
shipped one, issue 38): each set's official rates, and the difference with its standard error.

``--report A --against B`` pairs the trials of one world set run twice; two sets of different
worlds share no trial (their world indices may coincide but mean other worlds), so here each
set is summarized on its own and the difference is judged against sampling noise. The standard
error of a rate counts the world, not the trial, as the unit (a world's seeds are not
independent draws of the set's difficulty): ``sd(per-world means) / sqrt(worlds)``, and the
difference's is ``sqrt(se_a^2 + se_b^2)``.

    python -m emos.tools.barn.setcompare GENERATED.jsonl SHIPPED.jsonl [--json]
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

from .harness import EpisodeResult
from .trial_log import TrialLogError, read_results

RATES = (("success", lambda t: float(t.success)), ("collision", lambda t: float(t.collided)),
         ("timeout", lambda t: float(t.timeout)), ("metric", lambda t: float(t.metric)))


def rate_and_error(trials: list[EpisodeResult], value: Any) -> tuple[float, float]:
    """(mean over the trials, standard error with the world as the unit)."""
    if not trials:
        return math.nan, math.nan
    by_world: dict[int, list[float]] = {}
    for t in trials:
        by_world.setdefault(t.idx, []).append(value(t))
    means = np.asarray([np.mean(v) for v in by_world.values()])
    mean = float(np.mean([value(t) for t in trials]))
    se = float(np.std(means, ddof=1) / math.sqrt(len(means))) if len(means) > 1 else math.nan
    return mean, se


def compare(a: list[EpisodeResult], b: list[EpisodeResult]) -> list[dict[str, Any]]:
    rows = []
    for name, value in RATES:
        ma, sa = rate_and_error(a, value)
        mb, sb = rate_and_error(b, value)
        se = math.hypot(sa, sb)
        rows.append({"rate": name, "a": ma, "a_se": sa, "b": mb, "b_se": sb, "difference": ma - mb, "se": se,
                     "within_2se": bool(abs(ma - mb) <= 2 * se) if math.isfinite(se) else None})
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m emos.tools.barn.setcompare",
                                     description="two BARN result files of different world sets side by side")
    parser.add_argument("a", type=Path, help="results file (e.g. the generated set)")
    parser.add_argument("b", type=Path, help="results file (e.g. the shipped set run beside it)")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    try:
        (_, a), (_, b) = read_results(args.a), read_results(args.b)
    except TrialLogError as exc:
        print(f"barn setcompare: {exc}", file=sys.stderr)
        return 2
    rows = compare(a, b)
    if args.json:
        print(json.dumps({"a": str(args.a), "b": str(args.b), "a_trials": len(a), "b_trials": len(b), "rates": rows}))
        return 0
    from emos.tools.bench.common import table

    print(f"A = {args.a} ({len(a)} trials, {len({t.idx for t in a})} worlds); "
          f"B = {args.b} ({len(b)} trials, {len({t.idx for t in b})} worlds)")
    print(table(rows, [("rate", "rate", "s"), ("a", "A", ".3f"), ("a_se", "A se", ".3f"), ("b", "B", ".3f"),
                       ("b_se", "B se", ".3f"), ("difference", "A - B", "+.3f"), ("se", "se", ".3f"),
                       ("within_2se", "within 2 se", "")]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
