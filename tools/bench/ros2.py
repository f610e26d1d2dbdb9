"""``emos bench ros2``: half round trips between real rclpy nodes, and between an EMOS component
and an rclpy node through the ROS 2 bridge, in one run (the ``emos bench ipc`` ping-pong method).

Three pairs, each a ping and its echo, ``std_msgs/msg/UInt8MultiArray`` of ``payload_bytes``:

* ``rclpy-rclpy``: an rclpy pinger and an rclpy echo, two plain processes (rclpy message
  objects, Fast DDS with its default transports: shared memory between two local processes).
* ``emos-rclpy``: the pinger is an EMOS component (Event-triggered by the reply, default QoS) in a
  supervised System beside the run's ``Ros2BridgeComponent``; the echo is the same rclpy program.
  Each message goes ring -> bridge -> DDS -> echo, and back. The bridge talks loopback UDP (its
  default, docs/ros2.md) unless ``--fastdds shm``, where it uses Fast DDS's default transports
  (shared memory between local processes) as the rclpy nodes do.
* ``emos-direct-rclpy``: the same pinging component, its ping and echo topics declared
  ``transport="ros2"`` (emos.interop.ros2.direct): its own rclpy node puts them on the graph, no
  bridge. Its Fast DDS transports follow ``--fastdds`` as the bridge's do (``$EMOS_ROS2_FASTDDS``).

The echo republishes the message object it received (deserialize, serialize), as a user's relay
node would. The pinger stamps a sequence number in the first 8 bytes and takes the time when the
reply is usable as a numpy array; a reply with another number is not a sample (and any makes the
row an error); the first reply of a size is compared byte for byte. Samples are taken after
warm-up round trips; the ends are pinned, each to its own CPU (``--cpus``, as ``emos bench ipc``;
the bridge, a third process, is not pinned).

CPU per message (us of user + system CPU per round trip, over the sampled round trips):
``cpu_us_per_msg_ros`` is the rclpy echo's (the same program in both pairs);
``cpu_us_per_msg_emos`` is the EMOS side's, the pinging component plus the bridge (the component
alone for ``emos-direct-rclpy``; null for ``rclpy-rclpy``); ``cpu_us_per_msg_initiator`` is the pinging side's in both pairs (the rclpy
pinger, or the component plus the bridge), so the two pairs compare side by side. The bridge's
process is found once, when the warm-up ends, and must be the same process (pid and start time)
when the phase ends: a bridge not found, or restarted during the phase, makes the row an error
instead of a CPU figure that leaves it out or counts another process's life.

Discovery stays on this host (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`` unless set) on a
random domain (``--ros-domain-id``), so no other ROS 2 node is met.
"""
from __future__ import annotations

import argparse
import json
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

SIZES = [8, 921_600, 8 * 1024 * 1024]
PAIRS = ["rclpy-rclpy", "emos-rclpy", "emos-direct-rclpy"]
PING, PONG = "/bench/ros2_ping", "/bench/ros2_pong"
ROS_TYPE = "std_msgs/msg/UInt8MultiArray"
SEQ_BYTES = 8
_STARTUP_RESEND_S = 0.2  # re-send only until the first reply: discovery may not be done
_REPLY_TIMEOUT_S = 10.0  # after the first reply, a reply missing this long is lost: an error
_READY_TIMEOUT_S = 60.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from emos.tools.bench.ipc import _default_cpus

    parser.add_argument("--json", action="store_true", help="print the machine-readable result")
    parser.add_argument("--sizes", default=",".join(map(str, SIZES)), help="payload sizes in bytes (at least 8), comma-separated")
    parser.add_argument("--pairs", default=",".join(PAIRS), help=f"comma-separated, from {','.join(PAIRS)}")
    parser.add_argument("--messages", type=int, default=200, help="round trips per size and pair (fewer for large payloads)")
    parser.add_argument("--rounds", type=int, default=1, help="measure the pairs this many times, interleaved (the order reversed "
                        "every other round), pooling each pair's samples")
    parser.add_argument("--cpus", default=_default_cpus(), help="pin the two ends to these CPUs, 'A,B', or 'none' (as emos bench ipc)")
    parser.add_argument("--fastdds", choices=["default", "udp", "shm"], default="default",
                        help="Fast DDS transports: default (rclpy nodes: shared memory between local processes; the bridge: its "
                             "default, loopback UDP), udp (every participant on loopback UDP: like for like) or shm (every "
                             "participant, the bridge included, on Fast DDS's default transports: like for like)")
    parser.add_argument("--ros-domain-id", type=int, default=None, help="ROS 2 domain of the benchmark's nodes (default: a random one in 20..99)")


def _samples_for(size: int, wanted: int) -> int:
    from emos.tools.bench.ipc import _samples_for as ipc_samples

    return ipc_samples(size, wanted)


def _cpu_s(pid: int) -> float:
    import psutil

    t = psutil.Process(pid).cpu_times()
    return float(t.user + t.system)


def _seq_of(data: np.ndarray) -> int:
    return int.from_bytes(bytes(data[:SEQ_BYTES]), "little")


# ------------------------------------------------------------------ the rclpy programs
def _rclpy(cpu: int | None) -> tuple[Any, Any]:
    if cpu is not None:
        os.sched_setaffinity(0, {cpu})
    from emos.interop.ros2 import env

    env.ensure_loadable()
    env.prepare_package("std_msgs")
    import importlib

    import rclpy

    return rclpy, importlib.import_module("std_msgs.msg").UInt8MultiArray


def _peer_echo(domain: int, cpu: int | None) -> None:
    """Republishes every ping as a pong, from rclpy's message object."""
    rclpy, Msg = _rclpy(cpu)
    rclpy.init(domain_id=domain)
    node = rclpy.create_node("bench_echo")
    pub = node.create_publisher(Msg, PONG, 10)
    sub = node.create_subscription(Msg, PING, pub.publish, 10)
    print("ready", flush=True)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, Exception):  # SIGTERM: rclpy shut the context down
        pass
    finally:
        del sub
        node.destroy_node()  # explicitly: a participant left to exit keeps its /dev/shm files
        rclpy.try_shutdown()


def _peer_ping(domain: int, cpu: int | None, plan: list[tuple[int, int]], echo_pid: int) -> None:
    """Pings with rclpy message objects; prints one JSON line per size, then 'done'."""
    from emos.tools.bench.ipc_common import random_payload
    from emos.tools.bench.ipc_pingpong import warmup_round_trips

    rclpy, Msg = _rclpy(cpu)
    rclpy.init(domain_id=domain)
    node = rclpy.create_node("bench_ping")
    pub = node.create_publisher(Msg, PING, 10)
    replies: list[tuple[int, np.ndarray]] = []
    sub = node.create_subscription(Msg, PONG, lambda m: replies.append((time.perf_counter_ns(), np.frombuffer(m.data, np.uint8))), 10)
    msg = Msg()
    try:
        for size, count in plan:
            payload = random_payload(size)
            total = warmup_round_trips(count) + count
            rtts: list[int] = []
            seq = mismatches = 0
            abandoned: set[int] = set()
            cpu0 = (0.0, 0.0)
            error = None
            while len(rtts) < total and error is None:
                seq += 1
                payload[:SEQ_BYTES] = np.frombuffer(seq.to_bytes(SEQ_BYTES, "little"), np.uint8)
                sent_at = time.perf_counter_ns()
                msg.data = payload.tobytes()
                pub.publish(msg)
                while error is None:
                    rclpy.spin_once(node, timeout_sec=_STARTUP_RESEND_S)
                    got = None
                    while replies and got is None:
                        at, data = replies.pop(0)
                        if data.nbytes == size and _seq_of(data) == seq:
                            got = at, data
                        elif data.nbytes != size or _seq_of(data) not in abandoned:
                            mismatches += 1
                    if got is not None:
                        if not rtts and not np.array_equal(got[1], payload):
                            error = f"the echo of a {size} B payload came back with different bytes"
                        rtts.append(got[0] - sent_at)
                        if len(rtts) == total - count:  # warm-up done: CPU from here
                            cpu0 = (time.process_time(), _cpu_s(echo_pid))
                        break
                    waited = (time.perf_counter_ns() - sent_at) / 1e9
                    if not rtts and waited > _STARTUP_RESEND_S * 2 ** min(len(abandoned), 5):
                        # The echo may not be matched yet: a new number. Backing off, as the
                        # component pinger does: a slow first 8 MiB round trip is no flood.
                        abandoned.add(seq)
                        break
                    if rtts and waited > _REPLY_TIMEOUT_S:
                        error = f"no reply to ping {seq} within {_REPLY_TIMEOUT_S:g} s"
            row: dict[str, Any] = {"payload_bytes": size, "seq_mismatches": mismatches, "error": error}
            if error is None:
                row["half_us"] = [ns / 2e3 for ns in rtts[total - count:]]
                row["cpu_initiator_s"], row["cpu_ros_s"] = time.process_time() - cpu0[0], _cpu_s(echo_pid) - cpu0[1]
            print(json.dumps(row), flush=True)
            if error is not None:
                break
    except (KeyboardInterrupt, Exception) as exc:  # SIGTERM, or a bug: say so, then clean up
        print(json.dumps({"fatal": f"{type(exc).__name__}: {exc}"}), flush=True)
    finally:
        del sub
        node.destroy_node()
        rclpy.try_shutdown()
    print("done", flush=True)


# ------------------------------------------------------------------ the EMOS side
def _emos_ping(plan: list[tuple[int, int]], result_path: str, cpu: int | None, echo_pid: int, direct: bool = False) -> Any:
    """The pinging component (see ``emos bench ipc --mode component``, whose protocol it follows);
    ``direct``: its topics on the ROS 2 graph from its own process (``transport="ros2"``), no bridge."""
    import psutil

    from emos import Topic
    from emos.tools.bench.ipc_component import pinger_class

    Pinger = pinger_class(plan, result_path, cpu, ping_topic=PING)

    class Ping(Pinger):  # type: ignore[valid-type,misc]  # a class made at run time
        bridge: Any = None  # the bridge's psutil.Process, found when a phase's warm-up ends
        cpu0: tuple[float, float, float] | None = None  # CPU times when a phase's warm-up ended (see _cpu)
        cpu_error: str | None = None

        def _find_bridge(self) -> Any:
            """The bridge: a worker of the same System, whose CPU counts as EMOS's. A child that
            ends during the walk is skipped (it is not the bridge, which runs throughout)."""
            system = int(os.environ.get("EMOS_BENCH_SYSTEM_PID", "0") or 0)
            try:
                children = psutil.Process(system).children(recursive=True)
            except psutil.Error:
                return None
            for p in children:
                try:
                    if p.name().startswith("emos:ros2_bri"):
                        p.cpu_times()  # readable now, or skipped
                        return p
                except psutil.Error:
                    continue
            return None

        def _cpu(self) -> tuple[float, float, float]:
            if direct:  # no bridge: the component's process is the whole EMOS side
                return time.process_time(), 0.0, _cpu_s(echo_pid)
            t = self.bridge.cpu_times()  # psutil.Process checks it is the same process (pid and start time)
            return time.process_time(), float(t.user + t.system), _cpu_s(echo_pid)

        def _warmed_up(self) -> None:
            if direct:
                self.cpu_error = None
                self.cpu0 = self._cpu()
                return
            self.bridge, self.cpu0, self.cpu_error = self._find_bridge(), None, None
            if self.bridge is None:
                self.cpu_error = "the ROS 2 bridge's process was not found among the benchmark System's workers"
                return
            self.cpu0 = self._cpu()

        def _row(self, half_us: list[float]) -> dict[str, Any]:
            error = self.cpu_error
            cpu1 = None
            if error is None:
                try:
                    cpu1 = self._cpu()
                except psutil.Error as exc:  # NoSuchProcess also when the pid was reused
                    error = f"the ROS 2 bridge (pid {self.bridge.pid}) ended or was restarted during the phase ({type(exc).__name__})"
            row = {"payload_bytes": int(self.payload.nbytes), "half_us": half_us, "seq_mismatches": self.mismatches,
                   "startup_resends": self.resends, "error": error}
            if cpu1 is not None and self.cpu0 is not None:
                row.update(cpu_initiator_s=(cpu1[0] - self.cpu0[0]) + (cpu1[1] - self.cpu0[1]), cpu_ros_s=cpu1[2] - self.cpu0[2],
                           cpu_bridge_s=cpu1[1] - self.cpu0[1])
            return row

    topic = {"msg_type": "UInt8MultiArray", **({"transport": "ros2"} if direct else {})}  # default QoS: what recipes get
    return Ping(component_name="bench_ping", inputs=[Topic(name=PONG, **topic)], outputs=[Topic(name=PING, **topic)], trigger=Topic(name=PONG, **topic))


def _emos_system_main(plan: list[tuple[int, int]], result_path: str, cpu: int | None, echo_pid: int, domain: int, allowed: set[int],
                      fastdds: str = "udp", direct: bool = False) -> None:
    """The supervised System (the Ping component and the bridge, or with ``direct`` the Ping
    component alone, its topics ``transport="ros2"``), in a process of its own."""
    from emos.actors.ros2 import Ros2BridgeComponent, Ros2BridgeConfig
    from emos.interop.ros2.direct import ENV_FASTDDS
    from emos.interop.ros2.options import ENV_ROS2_DOMAIN
    from emos.supervisor.system import Package, System, SystemOptions

    os.sched_setaffinity(0, allowed)
    os.environ["EMOS_BENCH_SYSTEM_PID"] = str(os.getpid())
    ping = Package(components=[_emos_ping(plan, result_path, cpu, echo_pid, direct)], multiprocessing=True)
    if direct:  # the component's process inherits the domain and the Fast DDS transports
        os.environ[ENV_ROS2_DOMAIN], os.environ[ENV_FASTDDS] = str(domain), fastdds
        packages = [ping]
    else:
        bridge = Ros2BridgeComponent(config=Ros2BridgeConfig(topics=[PING, PONG], domain_id=domain, fastdds=fastdds))
        packages = [ping, Package(components=[bridge], multiprocessing=True)]
    system = System(packages, SystemOptions(heartbeat_timeout=10.0))
    os._exit(system.run())


# ------------------------------------------------------------------ the benchmark
class _Peer:
    """One rclpy helper: ``python -m emos.tools.bench.ros2 --peer ...``, dying with us. Its lines
    are read by a thread (lines that arrive together are not left in a buffer that select()
    would not see)."""

    def __init__(self, *args: object):
        import queue
        import threading

        self.role = f"{args[0]}"
        self.proc = subprocess.Popen([sys.executable, "-m", "emos.tools.bench.ros2", "--peer", str(os.getpid()), *map(str, args)],
                                     stdout=subprocess.PIPE, text=True)
        self.lines: queue.Queue[str | None] = queue.Queue()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for text in self.proc.stdout:
            self.lines.put(text.strip())
        self.lines.put(None)  # the helper closed its output: it ended

    def line(self, timeout: float) -> str:
        import queue

        try:
            text = self.lines.get(timeout=timeout)
        except queue.Empty:
            text = None
        if text is None:
            raise RuntimeError(f"rclpy benchmark helper ({self.role}) gave no output within {timeout:.0f} s (exit code {self.proc.poll()})")
        return text

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)  # rclpy's handler: the node is destroyed, its files removed
            try:
                self.proc.wait(20)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._reader.join(5.0)  # it reads to the end of the dead helper's output
        if self.proc.stdout is not None and not self._reader.is_alive():
            self.proc.stdout.close()


def _row(pair: str, raw: dict[str, Any]) -> dict[str, Any]:
    from emos.tools.bench.common import percentiles

    p = percentiles(raw["half_us"])
    n = len(raw["half_us"])
    per_msg = lambda s: round(s * 1e6 / n, 1)  # noqa: E731 - seconds over n round trips -> us per message
    return {"pair": pair, "payload_bytes": raw["payload_bytes"], "p50_us": round(p["p50"], 1), "p99_us": round(p["p99"], 1),
            "cpu_us_per_msg_emos": per_msg(raw["cpu_initiator_s"]) if pair != "rclpy-rclpy" else None,
            "cpu_us_per_msg_bridge": per_msg(raw["cpu_bridge_s"]) if pair == "emos-rclpy" else None,
            "cpu_us_per_msg_ros": per_msg(raw["cpu_ros_s"]), "cpu_us_per_msg_initiator": per_msg(raw["cpu_initiator_s"]),
            "round_trips": n, "seq_mismatches": raw["seq_mismatches"]}


def measure(pair: str, plan: list[tuple[int, int]], domain: int, cpus: tuple[int, int] | None,
            bridge_fastdds: str = "udp") -> tuple[list[dict[str, Any]], str | None]:
    """One row per size, and an error or None. ``bridge_fastdds``: the bridge's transports."""
    raws, error = _measure_raw(pair, plan, domain, cpus, bridge_fastdds)
    return [_row(pair, raw) for raw in raws], error


def _measure_raw(pair: str, plan: list[tuple[int, int]], domain: int, cpus: tuple[int, int] | None,
                 bridge_fastdds: str = "udp") -> tuple[list[dict[str, Any]], str | None]:
    """As :func:`measure`, the rows as the pingers report them (samples and CPU seconds)."""
    from emos.tools.bench import ipc_common
    from emos.tools.bench.ipc_component import await_result

    echo = _Peer("echo", domain, "none" if cpus is None else cpus[1])
    try:
        if echo.line(_READY_TIMEOUT_S) != "ready":
            return [], "the rclpy echo did not start"
        budget = 2 * _READY_TIMEOUT_S + sum(n for _, n in plan) * 0.5  # bounds a hang only: a loaded machine starts slowly
        if pair == "rclpy-rclpy":
            ping = _Peer("ping", domain, "none" if cpus is None else cpus[0], json.dumps(plan), echo.proc.pid)
            rows: list[dict[str, Any]] = []
            try:
                deadline = time.monotonic() + budget
                while (text := ping.line(max(1.0, deadline - time.monotonic()))) != "done":
                    raw = json.loads(text)
                    if "fatal" in raw or raw["error"]:
                        return rows, raw.get("fatal") or raw["error"]
                    rows.append(raw)
            finally:
                ping.stop()
            return rows, None
        with tempfile.TemporaryDirectory(prefix="emos-bench-ros2-") as tmp:
            result_path = str(Path(tmp) / "result.json")
            proc = ipc_common.start_child(_emos_system_main, (plan, result_path, None if cpus is None else cpus[0], echo.proc.pid, domain,
                                                               os.sched_getaffinity(0), bridge_fastdds, pair == "emos-direct-rclpy"),
                                             "emos:bench-sys")
            raws, error = await_result({"benchmark system": proc}, result_path, budget)
        failed = [raw for raw in raws if raw.get("error")]
        if failed:
            return raws[: raws.index(failed[0])], f"{failed[0]['payload_bytes']} B: {failed[0]['error']}"
        return raws, error
    finally:
        echo.stop()


def _usage_error(message: str) -> int:
    print(f"emos bench ros2: {message}", file=sys.stderr)
    return 2


def run(args: argparse.Namespace) -> int:
    from emos.interop.ros2 import env
    from emos.interop.ros2.options import check_domain
    from emos.tools.bench.ipc import _parse_cpus, _parse_list

    try:
        sizes = [int(s) for s in _parse_list(args.sizes)]
    except ValueError:
        return _usage_error(f"--sizes must be comma-separated byte counts, got {args.sizes!r}")
    if not sizes or min(sizes) < SEQ_BYTES:
        return _usage_error(f"--sizes must be at least {SEQ_BYTES} B each (the sequence number), got {args.sizes!r}")
    pairs = _parse_list(args.pairs)
    if not pairs or any(p not in PAIRS for p in pairs):
        return _usage_error(f"--pairs must be from {PAIRS}, got {args.pairs!r}")
    if args.messages < 1:
        return _usage_error(f"--messages must be at least 1, got {args.messages}")
    if args.rounds < 1:
        return _usage_error(f"--rounds must be at least 1, got {args.rounds}")
    cpus = _parse_cpus(args.cpus)
    if isinstance(cpus, str):
        return _usage_error(cpus)
    try:
        chosen = check_domain(args.ros_domain_id)
        domain = chosen if chosen is not None else random.randint(20, 99)
    except ValueError as exc:
        return _usage_error(str(exc))
    try:
        install = env.require()
    except env.Ros2Unavailable as exc:
        return _usage_error(str(exc))
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")  # inherited by every helper: meets no other host
    with tempfile.TemporaryDirectory(prefix="emos-bench-ros2-") as tmp:
        if args.fastdds == "udp":
            from emos.interop.ros2.fastdds import UDP_LOOPBACK_PROFILE

            # The bridge's own loopback-UDP profile for every participant; a profiles file
            # replaces the discovery-range setting (rmw would add shared memory back for it).
            profile = Path(tmp) / "udp.xml"
            profile.write_text(UDP_LOOPBACK_PROFILE)
            os.environ["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(profile)
            os.environ.pop("ROS_AUTOMATIC_DISCOVERY_RANGE", None)
        try:
            return _run_pairs(args, install, sizes, pairs, cpus, domain)
        finally:
            # A helper node stopped before rclpy took its signals over dies without removing its
            # Fast DDS shared-memory files: the benchmark removes what no live process holds.
            from emos.interop.ros2.fastdds_shm import remove_leftovers

            removed = remove_leftovers()
            if removed:
                print(f"emos bench ros2: removed {len(removed)} Fast DDS file(s) no live process held: {', '.join(sorted(removed))}",
                      file=sys.stderr)


def _run_pairs(args: argparse.Namespace, install: Any, sizes: list[int], pairs: list[str], cpus: tuple[int, int] | None, domain: int) -> int:
    from emos.tools.bench.common import table

    plan = [(size, _samples_for(size, args.messages)) for size in sizes]
    print(f"emos bench ros2: {install.describe()}, domain {domain}, "
          f"{'unpinned' if cpus is None else f'ends pinned to CPUs {cpus[0]} and {cpus[1]}'}; payloads {sizes}; Fast DDS {args.fastdds}", file=sys.stderr, flush=True)
    errors: dict[str, str] = {}
    # Rounds interleave the pairs (the order reversed every other round), so that a load that
    # changes during the run weighs on every pair alike; a pair's samples and CPU seconds are
    # pooled over the rounds. A pair that fails is measured no more.
    pooled: dict[tuple[str, int], dict[str, Any]] = {}
    for round_no in range(args.rounds):
        for pair in pairs if round_no % 2 == 0 else pairs[::-1]:
            if pair in errors:
                continue
            raws, error = _measure_raw(pair, plan, domain, cpus, "shm" if args.fastdds == "shm" else "udp")
            if error:
                errors[pair] = error
            for raw in raws:
                _pool(pooled.setdefault((pair, raw["payload_bytes"]), {}), raw)
            if args.rounds > 1:
                said = ", ".join(f"{r['payload_bytes']} B p50 {r['p50_us']:.0f} us" for r in (_row(pair, raw) for raw in raws))
                print(f"  round {round_no + 1} {pair}: {said or 'no result'}", file=sys.stderr, flush=True)
    results: list[dict[str, Any]] = []
    for pair in pairs:
        rows = [_row(pair, pooled[(pair, size)]) for size in sizes if (pair, size) in pooled]
        results += rows
        error = errors.get(pair)
        said = ", ".join(f"{r['payload_bytes']} B p50 {r['p50_us']:.0f} us p99 {r['p99_us']:.0f} us" for r in rows)
        print(f"  {pair}: {said or 'no result'}" + (f"; ERROR {error}" if error else ""), file=sys.stderr, flush=True)
    if args.json:
        doc: dict[str, Any] = {"results": results, "ros2": install.describe(), "cpus": None if cpus is None else list(cpus), "fastdds": args.fastdds}
        if errors:
            doc["errors"] = errors
        print(json.dumps(doc))
    else:
        print(table(results, [("pair", "pair", ""), ("payload_bytes", "bytes", ",d"), ("p50_us", "p50 us", ".1f"), ("p99_us", "p99 us", ".1f"),
                              ("cpu_us_per_msg_initiator", "CPU us/msg pinger", ".0f"), ("cpu_us_per_msg_ros", "CPU us/msg echo", ".0f")]))
        for pair, error in errors.items():
            print(f"ERROR {pair}: {error}", file=sys.stderr)
    return 1 if errors else 0


def _pool(into: dict[str, Any], raw: dict[str, Any]) -> None:
    """Add one round's row of a pair and size to ``into``: samples appended, counts and CPU seconds summed."""
    if not into:
        into.update(raw, half_us=list(raw["half_us"]))
        return
    into["half_us"] += raw["half_us"]
    for key in ("seq_mismatches", "cpu_initiator_s", "cpu_ros_s", "cpu_bridge_s"):
        if key in raw:
            into[key] = into.get(key, 0) + raw[key]


def _peer_main(argv: list[str]) -> None:
    """``--peer PARENT_PID echo DOMAIN CPU`` or ``--peer PARENT_PID ping DOMAIN CPU PLAN_JSON ECHO_PID``."""
    from emos.core.prctl import die_with

    parent, role, domain, cpu_text = int(argv[0]), argv[1], int(argv[2]), argv[3]
    if not die_with(parent, signal.SIGTERM):
        sys.exit(1)
    cpu = None if cpu_text == "none" else int(cpu_text)
    if role == "echo":
        _peer_echo(domain, cpu)
    else:
        _peer_ping(domain, cpu, [tuple(p) for p in json.loads(argv[4])], int(argv[5]))


if __name__ == "__main__":
    if sys.argv[1:2] == ["--peer"]:
        _peer_main(sys.argv[2:])
