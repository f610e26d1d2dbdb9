"""``emos bench events``: event and fallback latencies in real process trees.

* event_ms: publish of the triggering message -> first line of a component-method action in
  another process (the Monitor evaluates every armed event on each message), with 10 and 100
  armed events; topic_ms: the same topic's latency to an ordinary subscriber, with 0, 10 and
  100 events armed (the Monitor must not slow the topic down).
* fallback_ms: a component reports COMPONENT_FAILURE -> its fallback action's first line.
* recover_ms: COMPONENT_FAILURE -> the component is HEALTHY again through ``restart``
  (measured from the failure command to the first HEALTHY status of the new incarnation).

Clocks: CLOCK_MONOTONIC, shared by all processes of the machine.
"""
from __future__ import annotations

import argparse
import json
import os
import select
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from emos.core.rpc import RpcClient
from emos.launcher import DEFAULT_MONITOR_DEFER_MS, MAX_MONITOR_DEFER_MS
from emos.msgs import Int64
from emos.msgs.status import ComponentStatus
from emos.supervisor.launched import component_states
from emos.tools.bench.common import percentiles, table
from emos.tools.bench.restart import _wait_for_run
from emos.transport.context import RunContext
from emos.transport.pubsub import Publisher, Subscriber
from emos.transport.waker import Waker

SYSTEM = Path(__file__).with_name("events_system.py")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--samples", type=int, default=300, help="trigger messages per event configuration")
    parser.add_argument("--failures", type=int, default=40, help="failures per fallback measurement")
    parser.add_argument("--rate", type=float, default=50.0, help="trigger messages per second")
    parser.add_argument("--rounds", type=int, default=3, help="the event configurations take turns this many times (samples are split between rounds)")
    parser.add_argument("--monitor-nice", type=int, default=5, help="the Launcher's monitor_nice for the systems measured (default: %(default)s, the Launcher's default)")
    parser.add_argument("--monitor-defer-ms", type=float, default=None,
                        help="the Launcher's monitor_defer_ms for the systems measured (default: the Launcher's default)")
    parser.add_argument("--json", action="store_true")


class _Run:
    """One benchmark system under ``emos run``, reached through its run directory."""

    def __init__(self, env: dict[str, str]):
        self.proc = subprocess.Popen([sys.executable, "-m", "emos", "run", str(SYSTEM)], env={**os.environ, **env},
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        run_dir = _wait_for_run(self.proc.pid)
        self.ctx = RunContext(run_dir.name, run_dir, owner=False)
        self.rpc = RpcClient(run_dir / "supervisor.sock")
        self.waker = Waker(self.ctx)
        self.closeables: list[Any] = []

    def wait_active(self, names: list[str], timeout: float = 30.0) -> None:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            states = component_states(self.rpc.call("tree")["tree"])
            if all(states.get(n) == "active" for n in names):
                return
            time.sleep(0.05)
        raise TimeoutError(f"{names} not active within {timeout} s")

    def sub(self, topic: str, msg_type: Any) -> Subscriber:
        s = Subscriber(self.ctx, topic, msg_type, waker=self.waker, queue_size=64)
        self.closeables.append(s)
        return s

    def pub(self, topic: str) -> Publisher:
        p = Publisher(self.ctx, topic, Int64, publisher_id="bench", depth=16)
        self.closeables.append(p)
        return p

    def wait(self, until: Callable[[], bool], timeout: float) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if until():
                return True
            select.select([self.waker.fd], [], [], 0.01)
            self.waker.drain()
        return until()

    def close(self) -> None:
        for c in self.closeables:
            c.close()
        self.waker.close()
        try:
            self.rpc.call("stop", reason="benchmark finished")
        except Exception:
            pass
        self.rpc.close()
        try:
            self.proc.wait(30)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


def _events(n_events: int, samples: int, rate: float, firing: bool = True) -> dict[str, list[float]]:
    run = _Run({"EMOS_BENCH_MODE": "events", "EMOS_BENCH_EVENTS": str(n_events), "EMOS_BENCH_FIRING": "1" if firing else "0"})
    try:
        run.wait_active(["listener", "target"] + (["emos_monitor"] if n_events else []))
        topic_sub, event_sub = run.sub("/bench/topic_ns", Int64), run.sub("/bench/event_ns", Int64)
        pub = run.pub("/bench/trigger")
        topic_ms: list[float] = []
        event_ms: list[float] = []
        time.sleep(0.5)  # let every subscriber find the bench's publisher
        period = 1.0 / rate
        for i in range(samples + 10):
            pub.publish(Int64(data=time.monotonic_ns()))
            got_t: list[float] = []
            got_e: list[float] = []

            def done(got_t: list[float] = got_t, got_e: list[float] = got_e) -> bool:  # this sample's lists
                got_t.extend(m.data / 1e6 for m in topic_sub.take())
                got_e.extend(m.data / 1e6 for m in event_sub.take())
                return bool(got_t) and (bool(got_e) or not (n_events and firing))

            run.wait(done, 2.0)
            if i >= 10:  # warm-up
                topic_ms.extend(got_t[:1])
                event_ms.extend(got_e[:1])
            time.sleep(period)
        return {"topic": topic_ms, "event": event_ms}
    finally:
        run.close()


def _fallbacks(mode: str, failures: int) -> list[float]:
    run = _Run({"EMOS_BENCH_MODE": mode})
    try:
        run.wait_active(["faulty"])
        status = run.sub("/faulty/status", ComponentStatus)
        out_sub = run.sub("/bench/fallback_ns", Int64)
        pub = run.pub("/bench/fail")
        time.sleep(0.5)
        out: list[float] = []
        for i in range(failures + 3):
            status.take()
            out_sub.take()
            old_pid = run.rpc.call("tree")["tree"]["children"][0]["children"][0].get("pid")
            t0 = time.monotonic_ns()
            pub.publish(Int64(data=t0))
            if mode == "fallback":
                got: list[float] = []
                def arrived(got: list[float] = got) -> bool:  # this failure's list
                    got.extend(m.data / 1e6 for m in out_sub.take())
                    return bool(got)

                run.wait(arrived, 5.0)
                sample = got[0] if got else None
            else:
                healthy: list[float] = []

                def back(healthy: list[float] = healthy, old_pid: Any = old_pid, t0: int = t0) -> bool:  # this failure's
                    for s in status.take():
                        if s.status == ComponentStatus.STATUS_HEALTHY and s.pid != old_pid and s.lifecycle_state == "active":
                            healthy.append((time.monotonic_ns() - t0) / 1e6)
                    return bool(healthy)

                run.wait(back, 10.0)
                sample = healthy[0] if healthy else None
            if sample is not None and i >= 3:
                out.append(sample)
            time.sleep(0.3 if mode == "recover" else 0.1)
        return out
    finally:
        run.close()


def _p(values: list[float]) -> dict[str, float]:
    p = percentiles(values, (50, 95))
    return {"p50": round(p["p50"], 3), "p95": round(p["p95"], 3)}


def run(args: argparse.Namespace) -> int:
    if args.samples < 10 or args.failures < 5 or args.rate <= 0 or args.rounds < 1 or not 0 <= args.monitor_nice <= 19:
        print("emos bench events: --samples >= 10, --failures >= 5, --rate > 0, --rounds >= 1 and --monitor-nice 0..19 please", file=sys.stderr)
        return 2
    os.environ["EMOS_BENCH_MONITOR_NICE"] = str(args.monitor_nice)  # read by the measured systems
    if args.monitor_defer_ms is not None:
        if not 0 <= args.monitor_defer_ms <= MAX_MONITOR_DEFER_MS:
            print(f"emos bench events: --monitor-defer-ms 0..{MAX_MONITOR_DEFER_MS:g} please", file=sys.stderr)
            return 2
        os.environ["EMOS_BENCH_MONITOR_DEFER_MS"] = str(args.monitor_defer_ms)
    # The configurations take turns, round after round, so that a change in the machine's load
    # during the run falls on all of them alike (they are compared with each other).
    configs = {"events_0": (0, True), "events_10": (10, True), "events_100": (100, True), "armed_100": (100, False)}
    measured: dict[str, dict[str, list[float]]] = {k: {"topic": [], "event": []} for k in configs}
    per_round = max(10, args.samples // args.rounds)
    for r in range(args.rounds):
        for key, (n, firing) in configs.items():
            if not args.json:
                print(f"round {r + 1}/{args.rounds}: {key}", file=sys.stderr, flush=True)
            got = _events(n, per_round, args.rate, firing)
            for k in ("topic", "event"):
                measured[key][k].extend(got[k])
    fallback = _fallbacks("fallback", args.failures)
    recover = _fallbacks("recover", args.failures)
    result = {
        "event_ms": {k: _p(measured[k]["event"]) for k in ("events_10", "events_100")},
        "topic_ms": {k: _p(measured[k]["topic"]) for k in configs},
        "monitor_nice": args.monitor_nice,
        "monitor_defer_ms": DEFAULT_MONITOR_DEFER_MS if args.monitor_defer_ms is None else args.monitor_defer_ms,
        "fallback_ms": _p(fallback),
        "recover_ms": _p(recover),
        "samples": {"event": {k: len(measured[k]["event"]) for k in ("events_10", "events_100")}, "topic": {k: len(measured[k]["topic"]) for k in configs}, "fallback": len(fallback), "recover": len(recover)},
    }
    if args.json:
        print(json.dumps(result))
        return 0
    rows = [{"what": f"event -> action, {n} events", **result["event_ms"][f"events_{n}"]} for n in (10, 100)]
    rows += [{"what": f"topic -> subscriber, {n} events", **result["topic_ms"][f"events_{n}"]} for n in (0, 10, 100)]
    rows += [{"what": "topic -> subscriber, 100 armed, none firing", **result["topic_ms"]["armed_100"]}]
    rows += [{"what": "failure -> fallback action", **result["fallback_ms"]}, {"what": "failure -> healthy via restart", **result["recover_ms"]}]
    print(table(rows, [("what", "latency", "s"), ("p50", "p50 ms", ".3f"), ("p95", "p95 ms", ".3f")]))
    return 0
