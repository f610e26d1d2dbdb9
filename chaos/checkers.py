"""Checkers: judge a finished run from its history (nothing here talks to the system).

Recovery is measured from the fault (``restart``, ``zygote``, ``topic``) or from the end of a
lasting fault (``healthy``) to the first observation that shows the system whole again:

* ``restart``: the component runs as a *new* pid and reports HEALTHY;
* ``healthy``: the component reports HEALTHY (it may never have stopped);
* ``zygote``: a zygote that did not exist before the fault is running;
* ``topic``: a message arrives on the topic after the fault;
* ``recover``: the component reports a failure after the fault and then HEALTHY again (a fault
  that shows no failure at all is not a recovery: the fault missed).

A fault whose recovery could not be observed because the system under test ended on its own
first (a navigation mission that finished) within ``grace_s`` of it is marked ``cut`` and not
judged: the run gave it no time to recover. Workloads that drive a robot also get:

* :func:`moving_again`: for each fault, when the robot was commanded to move again afterwards;
* :func:`stops_on_stale`: for each fault that made a sensor stale (``stale: true`` in its fault
  record), every command on the drive's output topic from fault + ``within`` (the consumer's
  data timeout plus one control period) until the fault ended must be zero.
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
    cut: bool = False


def _status_timeline(history: History) -> dict[str, list[Record]]:
    out: dict[str, list[Record]] = {}
    for r in history.of("status"):
        out.setdefault(r.name, []).append(r)
    return out


def judge_faults(history: History, arrivals: dict[str, list[float]], grace_s: float = 3.0) -> list[FaultOutcome]:
    timeline = _status_timeline(history)
    exits = [r.t for r in history.of("exit")]  # the system's exit, and when the workload finished
    ended_at = min(exits) if exits else None
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
        elif expects == "recover":
            failed = next((s.t for s in timeline.get(target, []) if s.t >= f.t and s.detail.get("health") not in ("HEALTHY", None)), None)
            if failed is not None:
                at = next((s.t for s in timeline.get(target, []) if s.t > failed and s.detail.get("health") == "HEALTHY"), None)
        elif expects == "topic":
            at = next((t for t in arrivals.get(target, []) if t > f.t + 0.05), None)
        else:
            outcomes.append(FaultOutcome(f.t, f.name, target, expects, True, None))
            continue
        witness = f.detail.get("witness")
        if at is not None and witness and not any(t > f.t for t in arrivals.get(witness, [])):
            at = None  # recovered, but the message that had to follow the fault never came
        base = ends.get(f.t, f.t) if expects == "healthy" else f.t
        cut = at is None and ended_at is not None and ended_at < base + grace_s
        outcomes.append(FaultOutcome(f.t, f.name, target, expects, at is not None,
                                     None if at is None else round((at - base) * 1e3, 1), cut))
    return outcomes


def _moving(values: list[tuple[float, float]], after: float, eps: float) -> float | None:
    return next((t for t, speed in values if t > after and speed > eps), None)


def moving_again(history: History, commands: list[tuple[float, float]], outcomes: list[FaultOutcome], eps: float = 1e-3) -> list[float | None]:
    """For each fault: ms from the fault (from its end for the lasting faults the robot must ride
    out, ``healthy``) to the first command that moves the robot after the fault's recovery; None
    if the robot never moved again in the run (or the fault never recovered)."""
    ends = {r.detail.get("fault_t"): r.t for r in history.of("fault_end")}
    out: list[float | None] = []
    for o in outcomes:
        start = ends.get(o.t, o.t) if o.expects == "healthy" else o.t
        if o.expects != "none" and o.recover_ms is None:
            out.append(None)
            continue
        at = _moving(commands, start + (o.recover_ms or 0.0) / 1e3, eps)
        out.append(None if at is None else round((at - start) * 1e3, 1))
    return out


def stops_on_stale(history: History, commands: list[tuple[float, float]], within: float, eps: float = 1e-3) -> list[dict[str, Any]]:
    """Violations: stale-making faults during which a moving command was sent later than
    ``within`` s after the fault started. Each names the fault, the command's time and speed."""
    ends = {r.detail.get("fault_t"): r.t for r in history.of("fault_end")}
    exits = [r.t for r in history.of("exit")]
    problems = []
    exits = [min(exits)] if exits else []
    for f in history.of("fault"):
        if not f.detail.get("stale"):
            continue
        end = ends.get(f.t, exits[0] if exits else float("inf"))
        bad = [(t, v) for t, v in commands if f.t + within < t < end and v > eps]
        if bad:
            problems.append({"fault_t": f.t, "topic": f.detail.get("topic"), "command_t": bad[0][0],
                             "speed": round(bad[0][1], 4), "late_s": round(bad[0][0] - f.t, 3), "count": len(bad)})
    return problems


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
    judged = result["faults"] - result.get("cut", 0)
    if expect.get("all_recovered", True) and result["recovered"] < judged:
        lost = [f"{o['nemesis']}@{o['t']:.1f}s on {o['target']}" for o in result["outcomes"] if not o["recovered"] and not o.get("cut")]
        problems.append(f"{judged - result['recovered']} fault(s) not recovered: {', '.join(lost[:5])}")
    if result["faults"] < expect.get("min_faults", 0):
        problems.append(f"only {result['faults']} fault(s) injected, expected >= {expect['min_faults']}")
    leaks = result["leaks"]
    if leaks["shm"] or leaks["procs"] or leaks["dirs"] or result["zombies"] > expect.get("max_zombies", 0):
        problems.append(f"leaks: {leaks['shm']} segments, {leaks['procs']} processes, {leaks['dirs']} run dirs, {result['zombies']} zombies")
    if result["corrupt"]:
        problems.append(f"{result['corrupt']} corrupt message(s) delivered")
    bound = expect.get("recover_ms_p95")
    p95 = result["recover_ms"]["p95"]
    if bound is not None and p95 is not None and p95 > bound:
        problems.append(f"recovery p95 {p95:.0f} ms above the bound {bound} ms")
    for key in ("recover_ms_p95_kill", "recover_ms_p95_hang"):
        kind_p95 = result.get("recover_ms_by_kind", {}).get(key.rsplit("_", 1)[1], {}).get("p95")
        if expect.get(key) is not None and kind_p95 is not None and kind_p95 > expect[key]:
            problems.append(f"{key.rsplit('_', 1)[1]} recovery p95 {kind_p95:.0f} ms above the bound {expect[key]} ms")
    if expect.get("goal_reached", False):
        if result.get("goals") is None:
            problems.append("the workload wrote no goal result (it did not finish)")
        elif result.get("goals_reached", 0) < result["goals"]:
            problems.append(f"reached {result.get('goals_reached', 0)} of {result['goals']} goals")
    ladder = result.get("ladder")
    if ladder is not None:
        if ladder["violations"]:
            problems.append(f"fallback ladder: {len(ladder['violations'])} violation(s), first: {ladder['violations'][0]}")
        if ladder["complete"] < expect.get("ladder_min_complete", 1):
            problems.append(f"fallback ladder: reached its last step {ladder['complete']} time(s), expected >= {expect.get('ladder_min_complete', 1)}")
    if result.get("stale_violations"):
        v = result["stale_violations"][0]
        problems.append(f"{len(result['stale_violations'])} stale-input fault(s) where the robot was still commanded to move, "
                        f"first: {v['topic']} stalled at {v['fault_t']:.1f}s, command {v['speed']} at +{v['late_s']} s")
    if result.get("collisions"):
        problems.append(f"{result['collisions']} collision(s)")
    if result.get("unanswered"):
        problems.append(f"{len(result['unanswered'])} request(s) never answered, first: {result['unanswered'][0]}")
    if expect.get("min_requests") and (result.get("requests") or 0) < expect["min_requests"]:
        problems.append(f"only {result.get('requests') or 0} request(s) made, expected >= {expect['min_requests']}")
    return problems
