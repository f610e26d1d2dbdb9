"""What a chaos run shows people: a table for the terminal and a timeline picture.

The timeline has one row per component: its health over time (green HEALTHY, orange a reported
failure, grey between a death and the next report) with faults drawn as red bands from the
fault to its recovery, and, below, the message rate of each watched topic.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from emos.chaos.checkers import percentiles

_HEALTH_COLOURS = {"HEALTHY": "#2e9d4f", "UNKNOWN": "#b0b0b0"}


def aggregate(results: list[dict[str, Any]]) -> dict[str, Any]:
    """The issue's JSON shape, over every run of a scenario."""
    recover = [o["recover_ms"] for r in results for o in r["outcomes"] if o["recover_ms"] is not None and o["expects"] != "none"]
    with_goals = [r for r in results if r.get("goals")]
    return {
        "scenario": results[0]["scenario"] if results else None,
        "runs": len(results),
        "passed": sum(r["passed"] for r in results),
        "faults": sum(r["faults"] for r in results),
        "recovered": sum(r["recovered"] for r in results),
        "goal_rate": (sum(r.get("goals_reached", 0) >= r["goals"] for r in with_goals) / len(with_goals)) if with_goals else None,
        "collisions": sum(r.get("collisions") or 0 for r in results) if with_goals else None,
        "recover_ms": percentiles(recover),
        "leaks": {k: sum(r["leaks"][k] for r in results) for k in ("shm", "procs", "dirs")},
        "zombies": max((r["zombies"] for r in results), default=0),
        "corrupt": sum(r["corrupt"] for r in results),
        **({"answer_ms_at_fault": percentiles([v for r in results for v in r["answer_ms_at_fault"]["values"]])}
           if any("answer_ms_at_fault" in r for r in results) else {}),
    }


def table(results: list[dict[str, Any]]) -> str:
    head = f"{'seed':>5} {'exit':>4} {'faults':>6} {'recov':>5} {'p50 ms':>8} {'p95 ms':>8} {'goals':>7} {'coll':>4} {'leaks s/p/d':>11} {'corrupt':>7}  verdict"
    lines = [head, "-" * len(head)]
    for r in results:
        goals = f"{r.get('goals_reached', 0)}/{r['goals']}" if r.get("goals") else "-"
        p = r["recover_ms"]
        leaks = r["leaks"]
        lines.append(
            f"{r['seed']:>5} {str(r['exit_code']):>4} {r['faults']:>6} {r['recovered']:>5} {_ms(p['p50']):>8} {_ms(p['p95']):>8} "
            f"{goals:>7} {r.get('collisions') or 0:>4} {leaks['shm']:>3}/{leaks['procs']}/{leaks['dirs']:<5} {r['corrupt']:>7}  "
            + ("pass" if r["passed"] else "FAIL: " + "; ".join(r["problems"]))
        )
    kinds: dict[str, list[float]] = {}
    for r in results:
        for o in r["outcomes"]:
            if o["recover_ms"] is not None:
                kinds.setdefault(o["nemesis"], []).append(o["recover_ms"])
    if kinds:
        lines.append("")
        lines.append("recovery by fault kind: " + ", ".join(
            f"{k} n={len(v)} p50 {_ms(percentiles(v)['p50'])} p95 {_ms(percentiles(v)['p95'])} ms" for k, v in sorted(kinds.items())))
    return "\n".join(lines)


def _ms(v: float | None) -> str:
    return "-" if v is None else f"{v:.0f}"


def timeline_png(history_file: Path, result: dict[str, Any], out: Path) -> Path | None:
    """Draw the run's timeline; returns None (with the reason logged by the caller) without matplotlib."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    data = json.loads(Path(history_file).read_text())
    records = data["records"]
    status: dict[str, list[dict]] = {}
    for r in records:
        if r["kind"] == "status" and r["name"] != "zygote":
            status.setdefault(r["name"], []).append(r)
    end = max((r["t"] for r in records), default=1.0)
    names = sorted(status)
    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(11, 1.2 + 0.45 * max(1, len(names)) + 2.2), sharex=True,
                                  gridspec_kw={"height_ratios": [max(1, len(names)), 3]})
    for row, name in enumerate(names):
        seq = status[name]
        for i, s in enumerate(seq):
            t1 = seq[i + 1]["t"] if i + 1 < len(seq) else end
            health = s["detail"].get("health")
            colour = _HEALTH_COLOURS.get(health, "#e8902a") if s["detail"].get("pid") else "#b0b0b0"
            ax.broken_barh([(s["t"], max(0.001, t1 - s["t"]))], (row - 0.35, 0.7), color=colour)
    by_target = {o["t"]: o for o in result["outcomes"]}
    for r in records:
        if r["kind"] != "fault":
            continue
        o = by_target.get(r["t"])
        length = (o["recover_ms"] or 0) / 1e3 if o else 0
        target = str(r["detail"].get("target"))
        target_row = names.index(target) if target in names else None
        colour = "#d62728" if (o is None or o["recovered"]) else "#000000"
        if target_row is None:
            ax.axvline(r["t"], color=colour, lw=1, alpha=0.6)
        else:
            ax.broken_barh([(r["t"], max(0.05, length))], (target_row - 0.45, 0.9), facecolor="none", edgecolor=colour, hatch="///", lw=1)
        if len(result["outcomes"]) <= 40:  # past that, labels are ink, not information
            ax.text(r["t"], len(names) - 0.4, r["name"], rotation=90, fontsize=6, va="bottom", color=colour)
    ax.set_yticks(range(len(names)), names)
    ax.set_ylim(-0.6, len(names) + 0.8)
    ax.set_title(f"chaos {result['scenario']} seed {result['seed']}: {result['recovered']}/{result['faults']} faults recovered, "
                 f"recovery p95 {_ms(result['recover_ms']['p95'])} ms  (green healthy, orange failure, grey down; hatched: fault to recovery)",
                 fontsize=8)
    rates = result.get("rates") or {}
    for topic, series in rates.items():
        ax2.plot(series["t"], series["hz"], label=topic, lw=1)
    if rates:
        ax2.legend(fontsize=7, loc="lower right")
    ax2.set_ylabel("messages / s")
    ax2.set_xlabel("seconds since start")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
