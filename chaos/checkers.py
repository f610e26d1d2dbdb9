"""Checkers: judge a finished run from its history (nothing here talks to the system).

Recovery is measured from the fault (``restart``, ``zygote``, ``topic``) or from the end of a
lasting fault (``healthy``) to the first observation that shows the system whole again:

* ``restart``: the component runs as a *new* pid and reports HEALTHY;
* ``healthy``: the component reports HEALTHY (it may never have stopped);
* ``zygote``: a zygote that did not exist before the fault is running;
* ``topic``: a message arrives on the topic after the fault.
"""
from __future__ import annotations

from typing import Any

import numpy as np
from attrs import define

from emos.chaos.history import History, Record


@define
class FaultOutcome:
    t: float
    nemesis: str
    target: str
    expects: str
    recovered: bool
    recover_ms: float | None


def _status_timeline(history: History) -> dict[str, list[Record]]:
    out: dict[str, list[Record]] = {}
    for r in history.of("status"):
        out.setdefault(r.name, []).append(r)
    return out


def judge_faults(history: History, arrivals: dict[str, list[float]]) -> list[FaultOutcome]:
    timeline = _status_timeline(history)
    ends = {r.detail.get("fault_t"): r.t for r in history.of("fault_end")}
    outcomes = []
    for f in history.of("fault"):
        expects, target = f.detail.get("expects", "none"), str(f.detail.get("target", ""))
        at: float | None = None
        if expects == "restart":
            at = next((s.t for s in timeline.get(target, []) if s.t >= f.t and s.detail.get("pid") != f.detail.get("pid")
                       and s.detail.get("health") == "HEALTHY"), None)
        elif expects == "healthy":
            start = ends.get(f.t, f.t)
            before = [s for s in timeline.get(target, []) if s.t <= start]
            if before and before[-1].detail.get("health") == "HEALTHY":
                at = start
            else:
                at = next((s.t for s in timeline.get(target, []) if s.t > start and s.detail.get("health") == "HEALTHY"), None)
            if at is not None:
                at = max(at, start)
        elif expects == "zygote":
            known = set(f.detail.get("zygotes_before", []))
            at = next((s.t for s in timeline.get("zygote", []) if s.t >= f.t and set(s.detail.get("pids", [])) - known), None)
        elif expects == "topic":
            at = next((t for t in arrivals.get(target, []) if t > f.t + 0.05), None)
        else:
            outcomes.append(FaultOutcome(f.t, f.name, target, expects, True, None))
            continue
        base = ends.get(f.t, f.t) if expects == "healthy" else f.t
        outcomes.append(FaultOutcome(f.t, f.name, target, expects, at is not None,
                                     None if at is None else round((at - base) * 1e3, 1)))
    return outcomes


def percentiles(values: list[float]) -> dict[str, float | None]:
    if not values:
        return {"p50": None, "p95": None}
    arr = np.asarray(values, dtype=float)
    return {"p50": round(float(np.percentile(arr, 50)), 1), "p95": round(float(np.percentile(arr, 95)), 1)}


def verdict(result: dict[str, Any], expect: dict[str, Any]) -> list[str]:
    """Why a run failed (empty list: it passed)."""
    problems = []
    if result["exit_code"] != expect.get("exit_code", 0):
        problems.append(f"exit code {result['exit_code']}, expected {expect.get('exit_code', 0)}")
    if expect.get("all_recovered", True) and result["recovered"] < result["faults"]:
        lost = [f"{o['nemesis']}@{o['t']:.1f}s on {o['target']}" for o in result["outcomes"] if not o["recovered"]]
        problems.append(f"{result['faults'] - result['recovered']} fault(s) not recovered: {', '.join(lost[:5])}")
    leaks = result["leaks"]
    if leaks["shm"] or leaks["procs"] or leaks["dirs"] or result["zombies"] > expect.get("max_zombies", 0):
        problems.append(f"leaks: {leaks['shm']} segments, {leaks['procs']} processes, {leaks['dirs']} run dirs, {result['zombies']} zombies")
    if result["corrupt"]:
        problems.append(f"{result['corrupt']} corrupt message(s) delivered")
    bound = expect.get("recover_ms_p95")
    p95 = result["recover_ms"]["p95"]
    if bound is not None and p95 is not None and p95 > bound:
        problems.append(f"recovery p95 {p95:.0f} ms above the bound {bound} ms")
    if result.get("goals") and expect.get("goal_reached", False) and result.get("goals_reached", 0) < result["goals"]:
        problems.append(f"reached {result.get('goals_reached', 0)} of {result['goals']} goals")
    if result.get("collisions"):
        problems.append(f"{result['collisions']} collision(s)")
    return problems
