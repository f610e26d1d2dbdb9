"""The fallback-ladder checker: did the supervisor walk each component's ladder in the declared
order, with the declared retries?

The scenario declares the ladder it expects (``expect: fallback_ladder``)::

    fallback_ladder: {component: solver, steps: [reset_state, restart, switch_algorithm], max_retries: 2}

The facts come from the supervisor's own event log (copied into the history by the status
observer): one ``fallback`` event per attempt, with ``step``/``steps``, ``attempt``/``of`` and the
action's description. An *episode* starts with step 1, attempt 1 (after the component was healthy
long enough for its budget to reset). Within an episode every attempt must follow the previous
one as the ladder says: the next try of the same step while tries are left, else the first try
of the next step; never a step past the last, and ``gave_up`` only after the last try of the last
step. Each attempt's action must be the declared step's.
"""
from __future__ import annotations

from typing import Any

from emos.chaos.history import History
from emos.errors import ConfigError


class LadderSpecError(ConfigError):
    """``expect.fallback_ladder`` is malformed (named in the message)."""


def parse_spec(spec: Any, where: str) -> dict[str, Any]:
    if not isinstance(spec, dict) or not isinstance(spec.get("component"), str) or not isinstance(spec.get("steps"), list) or not spec["steps"]:
        raise LadderSpecError(f"{where}: fallback_ladder must be {{component: <name>, steps: [<action name>, ...], max_retries: <n>}}, got {spec!r}")
    retries = spec.get("max_retries", 1)
    if isinstance(retries, bool) or not isinstance(retries, int) or retries < 1:
        raise LadderSpecError(f"{where}: fallback_ladder.max_retries must be an int >= 1, got {retries!r}")
    return {"component": spec["component"], "steps": [str(s) for s in spec["steps"]], "max_retries": retries}


def check_ladder(history: History, spec: dict[str, Any]) -> dict[str, Any]:
    """``{"episodes", "attempts", "complete", "violations": [...]}`` for the declared ladder."""
    steps, tries, name = spec["steps"], spec["max_retries"], spec["component"]
    events = sorted((r for r in history.of("event") if r.detail.get("child") == name and r.name in ("fallback", "gave_up")),
                    key=lambda r: r.t)
    violations: list[str] = []
    episodes = complete = attempts = 0
    prev: tuple[int, int] | None = None
    for r in events:
        if r.name == "gave_up":
            if prev != (len(steps), tries):
                violations.append(f"t={r.t:.2f}s gave up after step {prev} instead of after step {len(steps)} try {tries}")
            prev = None
            continue
        attempts += 1
        step, attempt = int(r.detail.get("step", 0)), int(r.detail.get("attempt", 0))
        if r.detail.get("steps") != len(steps) or r.detail.get("of") != tries:
            violations.append(f"t={r.t:.2f}s ladder of {r.detail.get('steps')} step(s) x {r.detail.get('of')} tries, declared {len(steps)} x {tries}")
        if (step, attempt) == (1, 1):
            episodes += 1
        elif prev is None:
            violations.append(f"t={r.t:.2f}s an episode began at step {step} try {attempt}, not at step 1 try 1")
        else:
            expected = (prev[0], prev[1] + 1) if prev[1] < tries else (prev[0] + 1, 1)
            if (step, attempt) != expected:
                violations.append(f"t={r.t:.2f}s step {step} try {attempt} followed step {prev[0]} try {prev[1]} (expected step {expected[0]} try {expected[1]})")
        if 1 <= step <= len(steps) and steps[step - 1] not in str(r.detail.get("action", "")):
            violations.append(f"t={r.t:.2f}s step {step} ran {r.detail.get('action')!r}, declared {steps[step - 1]!r}")
        if step == len(steps):
            complete += attempt == 1
        prev = (step, attempt)
    return {"episodes": episodes, "attempts": attempts, "complete": complete, "violations": violations}
