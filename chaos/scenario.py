"""Scenario files and the runner: a recipe, a workload, a nemesis schedule and the checks.

A scenario is a YAML file (the shipped ones are in ``emos/chaos/scenarios/``)::

    name: sensor-kills
    description: the sensor demo under kills, hangs and a zygote kill
    recipe: recipes/sensor_demo.py     # absolute, or relative to the scenario file, the current
                                       # folder or the EMOS project folder
    duration: 40                       # seconds of faults (after warmup) + cooldown
    warmup: 3                          # quiet seconds before the first fault
    cooldown: 6                        # quiet seconds after the last one
    heartbeat_timeout: 2.0             # what the recipe uses (bounds hang recovery)
    topics: {/camera/rgb: Image, /scan: LaserScan}   # watched; stamped payloads CRC-checked
    env: {EMOS_NAV_OUT: "{out}/nav-{seed}"}           # for the recipe; {out} {seed} substituted
    proxies: [{name: model, upstream: "127.0.0.1:8000"}]  # exported as EMOS_CHAOS_PROXY_MODEL
    schedule:
      every: 2.0                       # seconds between faults, +- jitter
      jitter: 0.5
      order: random                    # or cycle
      nemeses:
        - {kind: kill, target: random}
        - {kind: hang, target: camera, duration: 3}
    motion: {topic: /cmd_vel, stale_within: 0.55}  # robots: the drive's command topic (Twist),
                                       # and the consumer's data timeout + one control period
    expect: {exit_code: 0, recover_ms_p95: 1000}
    short: {duration: 12}              # overrides for `--short` (CI)

``expect`` keys: ``exit_code`` (0), ``all_recovered`` (true), ``max_zombies`` (0),
``recover_ms_p95`` (all faults), ``recover_ms_p95_kill`` / ``recover_ms_p95_hang`` (by kind),
``min_faults``, ``goal_reached`` (every goal of the workload), ``fallback_ladder`` (the ladder
the fallback checker expects: see :mod:`emos.chaos.ladder`).

With ``motion`` the runner watches the command topic and adds, per fault, the time until the
robot was commanded to move again (``moving_ms``), and checks that every stale-making sensor
fault stopped the robot within ``stale_within`` s (violations fail the run). A run that ends on
its own (the workload finished) can cut the last faults short: those are reported as ``cut``
and not judged.

Workloads that have goals (navigation) write ``{"goals": n, "goals_reached": n, "collisions": n, "late_s": x}``
as JSON to the file named by ``EMOS_CHAOS_RESULT``; the runner reads it after the run.
"""
from __future__ import annotations

import json
import random
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import yaml
from attrs import define, field

from emos.chaos.checkers import judge_faults, moving_again, percentiles, stops_on_stale, verdict
from emos.chaos.history import History
from emos.chaos.ladder import check_ladder, parse_spec
from emos.chaos.nemesis import FaultProxy, Nemesis, NemesisError, make
from emos.chaos.nemesis.base import Compose
from emos.chaos.nemesis.proxy import ProxyFault
from emos.chaos.observe import StatusObserver, TopicObserver
from emos.chaos.services import Service
from emos.chaos.target import RunningSystem
from emos.errors import ConfigError

SHIPPED = Path(__file__).with_name("scenarios")
PROJECT_ROOT = Path(__file__).resolve().parents[1]


class ScenarioError(ConfigError):
    """A scenario file that cannot be run; the message names the file and the key."""


def shipped_scenarios() -> dict[str, Path]:
    return {p.stem: p for p in sorted(SHIPPED.glob("*.yaml"))}


def _number(data: dict, key: str, default: float, where: str, minimum: float = 0.0) -> float:
    value = data.get(key, default)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not value >= minimum:
        raise ScenarioError(f"{where}: {key} must be a number >= {minimum}, got {value!r}")
    return float(value)


@define
class Scenario:
    name: str
    source: Path
    recipe: Path
    description: str = ""
    duration: float = 30.0
    warmup: float = 3.0
    cooldown: float = 5.0
    heartbeat_timeout: float = 2.0
    topics: dict[str, str] = field(factory=dict)
    env: dict[str, str] = field(factory=dict)
    proxies: list[dict[str, Any]] = field(factory=list)
    services: list[dict[str, Any]] = field(factory=list)
    every: float = 2.0
    jitter: float = 0.0
    order: str = "random"
    nemeses: list[tuple[dict[str, Any], float]] = field(factory=list)
    expect: dict[str, Any] = field(factory=dict)
    motion: dict[str, Any] = field(factory=dict)

    @classmethod
    def load(cls, name_or_path: str | Path, short: bool = False) -> Scenario:
        path = Path(name_or_path)
        if not path.is_file():
            shipped = shipped_scenarios()
            if str(name_or_path) not in shipped:
                raise ScenarioError(f"no scenario file {str(name_or_path)!r} and no shipped scenario of that name; shipped: {', '.join(shipped)}")
            path = shipped[str(name_or_path)]
        try:
            data = yaml.safe_load(path.read_text())
        except yaml.YAMLError as exc:
            raise ScenarioError(f"{path}: not valid YAML: {exc}") from None
        if not isinstance(data, dict):
            raise ScenarioError(f"{path}: expected a mapping at the top level")
        overrides = data.pop("short", {}) or {}
        if short:
            if not isinstance(overrides, dict):
                raise ScenarioError(f"{path}: short must be a mapping of overrides")
            schedule_over = overrides.pop("schedule", {}) or {}
            data.update(overrides)
            data["schedule"] = {**(data.get("schedule") or {}), **schedule_over}
        known = {"name", "description", "recipe", "duration", "warmup", "cooldown", "heartbeat_timeout", "topics", "env", "proxies", "services", "schedule", "expect", "motion"}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ScenarioError(f"{path}: unknown key(s) {', '.join(unknown)}; known: {', '.join(sorted(known))}")
        if "recipe" not in data:
            raise ScenarioError(f"{path}: recipe is required (the recipe script to run)")
        schedule = data.get("schedule") or {}
        if not isinstance(schedule, dict):
            raise ScenarioError(f"{path}: schedule must be a mapping")
        entries = schedule.get("nemeses") or []
        if not isinstance(entries, list):
            raise ScenarioError(f"{path}: schedule.nemeses must be a list")
        nemeses = []
        for i, entry in enumerate(entries):
            where = f"{path}: schedule.nemeses[{i}]"
            make(entry, where)  # validate now, with the file and index in the message
            nemeses.append((entry, _number(entry, "duration", 0.0, where)))
        order = schedule.get("order", "random")
        if order not in ("random", "cycle"):
            raise ScenarioError(f"{path}: schedule.order must be random or cycle, got {order!r}")
        motion = data.get("motion") or {}
        if motion and (not isinstance(motion, dict) or not isinstance(motion.get("topic"), str) or set(motion) - {"topic", "stale_within"}):
            raise ScenarioError(f"{path}: motion must be a mapping {{topic: <Twist topic>, stale_within: <s>}}, got {motion!r}")
        if motion:
            _number(motion, "stale_within", 0.5, f"{path}: motion")
        for key in ("topics", "env", "expect"):
            if not isinstance(data.get(key) or {}, dict):
                raise ScenarioError(f"{path}: {key} must be a mapping")
        if "fallback_ladder" in (data.get("expect") or {}):
            parse_spec(data["expect"]["fallback_ladder"], f"{path}: expect")
        return cls(
            name=str(data.get("name", path.stem)), source=path, recipe=_find_recipe(str(data["recipe"]), path),
            description=str(data.get("description", "")),
            duration=_number(data, "duration", 30.0, str(path), 1.0), warmup=_number(data, "warmup", 3.0, str(path)),
            cooldown=_number(data, "cooldown", 5.0, str(path)), heartbeat_timeout=_number(data, "heartbeat_timeout", 2.0, str(path)),
            topics={str(k): str(v) for k, v in (data.get("topics") or {}).items()},
            env={str(k): str(v) for k, v in (data.get("env") or {}).items()}, proxies=list(data.get("proxies") or []), services=list(data.get("services") or []),
            every=_number(schedule, "every", 2.0, f"{path}: schedule", 0.05), jitter=_number(schedule, "jitter", 0.0, f"{path}: schedule"),
            order=order, nemeses=nemeses, expect=dict(data.get("expect") or {}), motion=dict(motion),
        )


def _find_recipe(text: str, scenario_path: Path) -> Path:
    candidates = [Path(text)] if Path(text).is_absolute() else [scenario_path.parent / text, Path.cwd() / text, PROJECT_ROOT / text]
    for c in candidates:
        if c.is_file():
            return c.resolve()
    raise ScenarioError(f"{scenario_path}: recipe {text!r} not found (looked in {', '.join(str(c) for c in candidates)})")


def run_scenario(sc: Scenario, seed: int, out_dir: Path, progress: Callable[[str], None] = print) -> dict[str, Any]:
    """One seeded run: start the recipe, inject the schedule, stop, judge. Returns the result dict."""
    out_dir.mkdir(parents=True, exist_ok=True)
    rng = random.Random(seed)
    history = History()
    proxies: dict[str, FaultProxy] = {}
    services: list[Service] = []
    # {out} and {seed} in env values: per-run output places for the workload (e.g. its log folder)
    env = {k: v.replace("{out}", str(out_dir)).replace("{seed}", str(seed)) for k, v in sc.env.items()}
    result_file = out_dir / f"workload-{seed}.json"
    result_file.unlink(missing_ok=True)
    env["EMOS_CHAOS_RESULT"] = str(result_file)
    env["EMOS_CHAOS_SEED"] = str(seed)
    env["EMOS_CHAOS"] = "1"  # lets the sensor nemesis switch on faults in publish paths (emos.core.faults)
    nemeses: list[tuple[Nemesis, float]] = []
    pending: list[tuple[float, Nemesis]] = []
    system: RunningSystem | None = None
    observers: list[Any] = []
    try:
        for spec in sc.services:
            service = Service(spec, out_dir)
            progress(f"[{sc.name} seed {seed}] starting service {service.name} on {service.address}")
            services.append(service)
            service.start()
            env[f"EMOS_CHAOS_SERVICE_{service.name.upper()}"] = service.address
        by_name = {s.name: s.address for s in services}
        for p in sc.proxies:
            upstream = str(p.get("upstream"))
            if upstream.startswith("service:"):
                if upstream[8:] not in by_name:
                    raise ScenarioError(f"{sc.source}: proxy {p.get('name')!r} fronts unknown service {upstream[8:]!r}; services: {', '.join(by_name) or 'none'}")
                upstream = by_name[upstream[8:]]
            proxy = FaultProxy(str(p.get("name")), upstream, str(p.get("listen", "127.0.0.1:0")))
            for toxic, params in (p.get("toxics") or {}).items():  # standing toxics, e.g. a slow link
                proxy.set_toxic(str(toxic), **(params or {}))
            host, port = proxy.start()
            proxies[proxy.name] = proxy
            env[f"EMOS_CHAOS_PROXY_{proxy.name.upper()}"] = f"{host}:{port}"
        for spec, duration in sc.nemeses:
            n = make(spec)
            for part in (n.parts if isinstance(n, Compose) else [n]):
                if isinstance(part, ProxyFault):
                    part.proxies = proxies
            nemeses.append((n, duration))
        total = sc.warmup + sc.duration
        # The recipe's own --duration is only a backstop: the runner stops it in order itself.
        system = RunningSystem(sc.recipe, duration=total + 60.0, log_path=out_dir / f"run-{seed}.log", env=env)
        progress(f"[{sc.name} seed {seed}] starting {sc.recipe.name}")
        system.start()
        history.add("note", "started", run_id=system.run_id)
        status = StatusObserver(system, history)
        observers.append(status)
        watched = dict(sc.topics)
        if sc.motion:
            watched.setdefault(sc.motion["topic"], "Twist")
        topics = TopicObserver(system, history, watched) if watched else None
        if topics is not None:
            observers.append(topics)
        for o in observers:
            o.start()
        for n, _ in nemeses:
            n.bind(system, history, rng)
        t_start = history.now()
        next_fault = t_start + sc.warmup
        fault_end = t_start + sc.duration + sc.warmup - sc.cooldown
        turn = 0
        last_progress = 0.0
        while system.alive and history.now() < t_start + total:
            now = history.now()
            for due, n in [p for p in pending if p[0] <= now]:
                n.stop()
                pending.remove((due, n))
            if nemeses and now >= next_fault and now < fault_end:
                n, duration = nemeses[turn % len(nemeses)] if sc.order == "cycle" else rng.choice(nemeses)
                turn += 1
                if all(n is not m for _, m in pending):  # one instance of a lasting fault at a time
                    try:
                        record = n.start()
                    except NemesisError:
                        raise
                    except Exception as exc:  # the system may be mid-restart: note it, try the next one
                        history.add("note", n.kind, error=f"{type(exc).__name__}: {exc}")
                        record = None
                    if record is not None:
                        progress(f"[{sc.name} seed {seed}] t={record.t:6.1f}s {n.kind} -> {record.detail.get('target')}")
                        if duration > 0:
                            pending.append((history.now() + duration, n))
                next_fault = now + sc.every + rng.uniform(-sc.jitter, sc.jitter)
            if now - last_progress >= 5.0:
                last_progress = now
                faults = len(history.of("fault"))
                progress(f"[{sc.name} seed {seed}] t={now:6.1f}s faults {faults}")
            time.sleep(0.01)
    finally:
        for _, n in pending:
            n.stop()
        for n, _ in nemeses:
            if n.active is not None:
                n.stop()
        exit_code = None
        if system is not None and system.alive and observers:
            observers[0].finish()  # the supervisor's last events, while it still answers
        if system is not None and system.proc is not None:  # None: interrupted before the recipe was started
            exit_code = system.stop() if system.alive else system.wait(30)
        for o in observers:
            o.halt.set()
            o.join(timeout=5)
        for proxy in proxies.values():
            proxy.stop()
        for service in services:
            service.stop()
    assert system is not None
    history.add("exit", "system", code=exit_code)
    time.sleep(0.2)  # let the kernel finish tearing down the last processes before counting leaks
    leaks = system.leaks()
    status_obs = observers[0]
    topic_obs = observers[1] if len(observers) > 1 else None
    workload: dict[str, Any] = {}
    workload_error = None
    if result_file.is_file():
        # When the workload wrote its result it had finished and was ending the run: faults
        # after that point may not get to recover (the checker reports them as cut).
        history.records_event(result_file.stat().st_mtime - history.wall_t0, "workload", {}, kind="exit")
        try:
            workload = json.loads(result_file.read_text())
        except (OSError, ValueError) as exc:
            workload_error = f"{result_file}: {exc}"
    outcomes = judge_faults(history, dict(topic_obs.arrivals) if topic_obs else {}, grace_s=sc.heartbeat_timeout + 2.0)
    recover = [o.recover_ms for o in outcomes if o.recover_ms is not None and o.expects != "none"]
    motion_topic = sc.motion.get("topic") if sc.motion else None
    if motion_topic and not motion_topic.startswith("/"):
        motion_topic = "/" + motion_topic
    commands = list(topic_obs.commands.get(motion_topic, [])) if topic_obs and motion_topic else []
    moving = moving_again(history, commands, outcomes) if motion_topic else [None] * len(outcomes)
    result: dict[str, Any] = {
        "scenario": sc.name, "seed": seed, "run_id": system.run_id, "exit_code": exit_code,
        "faults": len(outcomes), "recovered": sum(o.recovered for o in outcomes),
        "recover_ms": percentiles(recover),
        "recover_ms_by_kind": {k: percentiles([o.recover_ms for o in outcomes if o.nemesis == k and o.recover_ms is not None])
                               for k in sorted({o.nemesis for o in outcomes})},
        "cut": sum(o.cut for o in outcomes),
        "outcomes": [{"t": o.t, "nemesis": o.nemesis, "target": o.target, "expects": o.expects,
                      "recovered": o.recovered, "recover_ms": o.recover_ms, "cut": o.cut, "moving_ms": m}
                     for o, m in zip(outcomes, moving)],
        "moving_ms": percentiles([m for m in moving if m is not None]),
        "stale_violations": stops_on_stale(history, commands, float(sc.motion.get("stale_within", 0.5))) if motion_topic else [],
        "leaks": {k: leaks[k] for k in ("shm", "procs", "dirs")}, "leak_detail": leaks["detail"],
        "zombies": status_obs.max_zombies,
        "received": dict(topic_obs.received) if topic_obs else {},
        "rates": _rates(topic_obs.arrivals) if topic_obs else {},
        "corrupt": sum(topic_obs.corrupt.values()) if topic_obs else 0,
        "log": str(system.log_path),
    }
    if workload:
        result.update({k: workload.get(k) for k in ("goals", "goals_reached", "collisions", "late_s", "requests", "answered", "unanswered", "answer_ms")})
    if workload_error:
        result["workload_error"] = workload_error
    if "fallback_ladder" in sc.expect:
        result["ladder"] = check_ladder(history, parse_spec(sc.expect["fallback_ladder"], str(sc.source)))
    if result.get("answer_ms"):
        # Time to answer the requests in flight when a fault struck (asked from 1.5 s before it
        # to 1 s after): what a user waiting on the robot sees when its model server drops.
        at_fault = [ms for f in history.of("fault") for asked, ms in result["answer_ms"]
                    if history.wall_t0 + f.t - 1.5 <= asked <= history.wall_t0 + f.t + 1.0]
        result["answer_ms_at_fault"] = percentiles(at_fault) | {"n": len(at_fault), "values": at_fault}
        result["answer_ms"] = percentiles([ms for _, ms in result["answer_ms"]]) | {"n": len(result["answer_ms"])}
    result["problems"] = verdict(result, sc.expect)
    result["passed"] = not result["problems"]
    (out_dir / f"history-{seed}.json").write_text(history.to_json())
    result["history"] = str(out_dir / f"history-{seed}.json")
    return result


def _rates(arrivals: dict[str, list[float]], bin_s: float = 0.5) -> dict[str, dict[str, list[float]]]:
    """Messages per second of each watched topic, in bins (for the timeline)."""
    import numpy as np

    out = {}
    for topic, times in arrivals.items():
        if not times:
            continue
        edges = np.arange(0.0, max(times) + bin_s, bin_s)
        counts, _ = np.histogram(times, bins=edges)
        out[topic] = {"t": [round(float(e), 2) for e in edges[:-1]], "hz": [float(c) / bin_s for c in counts]}
    return out
