"""``emos bench ipc --mode component``: ping-pong through two real components.

The transport mode measures the rings with a hand-made event loop at history depth 2. This mode
measures what a component gets: two ``BaseComponent``s in supervised processes (zygote, pidfd,
heartbeats and all, under a real :class:`~emos.supervisor.system.System`), their topics declared
with the default QoS (KEEP_LAST 10), each message delivered through the node's wake-up path to an
Event-triggered ``_execution_step`` that decodes it, and the ``ComponentStatus`` stream every
component publishes (its heartbeat, and after a step that changed it).

* ``ping`` (the initiator) publishes a ``UInt8MultiArray`` on ``/bench/ping``;
* ``echo``, triggered by ``/bench/ping``, publishes the message it decoded on ``/bench/pong``;
* ``ping``, triggered by ``/bench/pong``, takes the time and sends the next one.

Every message carries a sequence number in its first 8 bytes. Each reply is checked against the
number in flight: a reply with another number (a stale message from the ring's history, a
duplicate) is counted as a mismatch and is not a sample, and any mismatch makes the result an
error. The first reply of each size is also compared byte for byte with what was sent.
"""
from __future__ import annotations

import json
import os
import signal
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from emos.tools.bench import ipc_common
from emos.tools.bench.common import percentiles
from emos.tools.bench.ipc_common import random_payload
from emos.tools.bench.ipc_pingpong import warmup_round_trips

PING, PONG = "/bench/ping", "/bench/pong"
SEQ_BYTES = 8
# Re-send a ping only while the echo may not be subscribed yet (before the first reply); after
# that, a reply missing this long is a lost message and ends the measurement with an error.
_STARTUP_RESEND_S = 0.2
_REPLY_TIMEOUT_S = 10.0


def _seq_of(data: np.ndarray) -> int:
    return int.from_bytes(bytes(data[:SEQ_BYTES]), "little")


def qos_depth() -> int:
    """The history depth the components' topics get: the default QoS's."""
    from emos.config.qos import QoSConfig

    return int(QoSConfig().queue_size)


def pinger_class(plan: list[tuple[int, int]], result_path: str, cpu: int | None, ping_topic: str = PING) -> Any:
    """The initiating component's class, for this mode and for ``emos bench ros2``: it pings with
    numbered payloads, checks each reply against the number in flight, and writes
    ``{"results": [...], "error": ...}`` to ``result_path`` when every phase (size, count) of
    ``plan`` is done; it publishes on ``ping_topic``. Subclasses give ``_row(half_us)``, the result row of a phase, and may use
    ``_warmed_up()``, called when the warm-up round trips of a phase are over."""
    from emos import BaseComponent
    from emos.msgs import UInt8MultiArray

    class Pinger(BaseComponent):
        def custom_on_activate(self) -> None:
            if cpu is not None:
                os.sched_setaffinity(0, {cpu})
            self.phase = 0
            self.results: list[dict[str, Any]] = []
            self.finished = False
            self._start_phase()
            self.create_timer(0.05, self._watchdog)

        def _row(self, half_us: list[float]) -> dict[str, Any]:
            raise NotImplementedError

        def _warmed_up(self) -> None:
            """Warm-up over: the measured round trips start (a hook for CPU accounting)."""

        def _start_phase(self) -> None:
            size, count = plan[self.phase]
            self.payload = random_payload(size)
            self.msg = UInt8MultiArray(data=self.payload)
            self.count, self.total = count, warmup_round_trips(count) + count
            self.rtts_ns: list[int] = []
            self.seq = self.mismatches = self.resends = 0
            self.abandoned: set[int] = set()
            self._send()

        def _send(self) -> None:
            self.seq += 1
            self.payload[:SEQ_BYTES] = np.frombuffer(self.seq.to_bytes(SEQ_BYTES, "little"), np.uint8)
            self.sent_at = time.perf_counter_ns()
            self.publish(ping_topic, self.msg)

        def _watchdog(self) -> None:
            if self.finished:
                return
            waited = (time.perf_counter_ns() - self.sent_at) / 1e9
            # Backing off (0.2, 0.4, ... 6.4 s): a large payload whose first round trip takes
            # longer than 0.2 s must not be re-sent in a flood (8 MiB through a loaded bridge).
            if not self.rtts_ns and waited > _STARTUP_RESEND_S * 2 ** min(self.resends, 5):
                # The echo may not have been listening yet. A new number, so that a late reply
                # to the abandoned ping is recognised as such, not taken as a sample.
                self.resends += 1
                self.abandoned.add(self.seq)
                self._send()
            elif self.rtts_ns and waited > _REPLY_TIMEOUT_S:
                self._finish(f"no reply to ping {self.seq} within {_REPLY_TIMEOUT_S:g} s")

        def _execution_step(self, msg: Any = None, topic: Any = None) -> None:
            self.health_status.set_healthy()
            if msg is None or self.finished:
                return
            now = time.perf_counter_ns()
            data = msg.data
            if data.nbytes != self.payload.nbytes or _seq_of(data) != self.seq:
                if data.nbytes != self.payload.nbytes or _seq_of(data) not in self.abandoned:
                    self.mismatches += 1  # a stale, duplicated or foreign reply: not a sample
                return
            if not self.rtts_ns and not np.array_equal(data, self.payload):
                self._finish(f"the echo of a {self.payload.nbytes} B payload came back with different bytes")
                return
            self.rtts_ns.append(now - self.sent_at)
            if len(self.rtts_ns) == self.total - self.count:
                self._warmed_up()
            if len(self.rtts_ns) < self.total:
                self._send()
                return
            self.results.append(self._row([ns / 2e3 for ns in self.rtts_ns[self.total - self.count :]]))
            self.phase += 1
            if self.phase < len(plan):
                self._start_phase()
            else:
                self._finish(None)

        def _finish(self, error: str | None) -> None:
            self.finished = True
            tmp = result_path + ".tmp"
            with open(tmp, "w") as f:
                json.dump({"results": self.results, "error": error}, f)
            os.replace(tmp, result_path)  # the benchmark sees all of it or nothing

    return Pinger


def _components(plan: list[tuple[int, int]], result_path: str, cpus: tuple[int, int] | None, transport: str = "auto",
                label: str = "emos_component") -> list[Any]:
    """The two components, ``[echo, ping]``; built in the benchmark process, forked into workers
    by the zygote. ``transport``: their topics' (``"zenoh"``: ``emos bench net --mode component``,
    each in a run of its own); ``label``: the ``transport`` their result rows carry."""
    from emos import BaseComponent, Topic

    class Echo(BaseComponent):
        def custom_on_activate(self) -> None:
            if cpus is not None:
                os.sched_setaffinity(0, {cpus[1]})

        def _execution_step(self, msg: Any = None, topic: Any = None) -> None:
            if msg is not None:
                self.publish(PONG, msg)
            self.health_status.set_healthy()

    Pinger = pinger_class(plan, result_path, None if cpus is None else cpus[0])

    class Ping(Pinger):  # type: ignore[valid-type,misc]  # a class made at run time
        def _row(self, half_us: list[float]) -> dict[str, Any]:
            p = percentiles(half_us)
            return {"transport": label, "payload_bytes": int(self.payload.nbytes), "p50_us": round(p["p50"], 2),
                    "p95_us": round(p["p95"], 2), "p99_us": round(p["p99"], 2), "round_trips": len(half_us),
                    "seq_mismatches": self.mismatches, "startup_resends": self.resends}

    topic = {"msg_type": "UInt8MultiArray", "transport": transport}  # default QoS: what recipes get
    echo = Echo(component_name="bench_echo", inputs=[Topic(name=PING, **topic)], outputs=[Topic(name=PONG, **topic)], trigger=Topic(name=PING, **topic))
    ping = Ping(component_name="bench_ping", inputs=[Topic(name=PONG, **topic)], outputs=[Topic(name=PING, **topic)], trigger=Topic(name=PONG, **topic))
    return [echo, ping]


def _system_main(plan: list[tuple[int, int]], result_path: str, cpus: tuple[int, int] | None, allowed: set[int]) -> None:
    """The supervised system, in a process of its own (it becomes a subreaper and forks a zygote).
    Unpinned itself: each component pins its own process (``--cpus``)."""
    from emos.supervisor.system import Package, System, SystemOptions

    os.sched_setaffinity(0, allowed)

    system = System([Package(components=_components(plan, result_path, cpus), multiprocessing=True)], SystemOptions(heartbeat_timeout=5.0))
    os._exit(system.run())


def latency(sizes: list[int], messages: int, samples_for: Any) -> tuple[list[dict[str, Any]], str | None]:
    """One row per size, and an error (None if every reply was the one expected)."""
    from emos.tools.bench.ipc_common import start_child

    too_small = check_sizes(sizes)
    if too_small:
        return [], too_small
    plan = [(size, samples_for(size, messages)) for size in sizes]
    budget = 60.0 + sum(warmup_round_trips(n) + n for _, n in plan) * 0.02
    with tempfile.TemporaryDirectory(prefix="emos-bench-") as tmp:
        result_path = str(Path(tmp) / "result.json")
        allowed = os.sched_getaffinity(0)
        proc = start_child(_system_main, (plan, result_path, ipc_common.PLACEMENT, allowed), "emos:bench-sys")
        return await_result({"benchmark system": proc}, result_path, budget)


def check_sizes(sizes: list[int]) -> str | None:
    """Why these payload sizes cannot be measured by the components, or None."""
    if min(sizes) < SEQ_BYTES:
        return f"component mode needs payloads of at least {SEQ_BYTES} B (the sequence number), got {min(sizes)}"
    return None


def await_result(systems: dict[str, Any], result_path: str, budget: float) -> tuple[list[dict[str, Any]], str | None]:
    """Wait for the Ping component's result file, then stop ``systems`` (name -> started process
    running a ``System``) whatever happened: rows and an error, as :func:`latency` returns them."""
    from emos.tools.bench.ipc_common import stop_child

    try:
        deadline = time.monotonic() + budget
        while not os.path.exists(result_path):
            for name, proc in systems.items():
                if not proc.is_alive():
                    return [], f"the {name} exited with code {proc.exitcode} before reporting"
            if time.monotonic() > deadline:
                return [], f"no result from the component ping-pong within {budget:.0f} s"
            time.sleep(0.05)
        with open(result_path) as f:
            doc = json.load(f)
    finally:
        for proc in systems.values():
            if proc.is_alive():
                os.kill(proc.pid, signal.SIGTERM)  # its supervisor stops its components in order
        for proc in systems.values():
            stop_child(proc, 30.0)
    rows, error = doc["results"], doc["error"]
    mismatches = sum(r["seq_mismatches"] for r in rows)
    if error is None and mismatches:
        error = f"{mismatches} repl(ies) carried the wrong sequence number"
    return rows, error


__all__ = ["latency", "pinger_class"]
