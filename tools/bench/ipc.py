"""``emos bench ipc``: latency and throughput between two processes, EMOS topics against
``multiprocessing.Queue`` and ``multiprocessing.Pipe`` carrying the same bytes, in one run.

EMOS goes through the path a component uses: encode into the ring, FIFO wake-up, uvloop reader,
read, decode (arrays become numpy views). The ``multiprocessing`` peers carry ``bytes`` that the
receiver turns into a numpy array with ``np.frombuffer``.

Latency, two methods (``--method``), the same for all three transports:

* ``pingpong`` (default): process A sends, process B decodes and sends the same message back,
  A takes the time once the reply is decoded; a sample is half of A's round trip
  (``time.perf_counter_ns``). This is how the issue's reference numbers were measured (Pipe
  about 24 us at 8 B and 1.2 ms at 921,600 B, Queue about 2.0 ms), so it is the default.
* ``oneway``: the sender stamps each message, paces them by spinning so no queue builds up,
  and the receiver subtracts the stamp from its clock (see :mod:`.ipc_oneway`). On this
  Firecracker VM a vCPU that idles between messages halts and wakes with cold caches, so this
  method mostly measures the hypervisor's wake-up (the Pipe's 8 B latency reads 84 us one way
  against 30 us as half a round trip). Kept to show that effect.

Throughput, for either method: messages received per second while the sender sends flat out,
one way (EMOS rings drop what a slow reader misses; Pipe and Queue block the sender instead).
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from typing import Any

from emos.core.node import wake_spin_setting
from emos.tools.bench import ipc_common, ipc_component, ipc_oneway, ipc_peers, ipc_pingpong
from emos.tools.bench.common import percentiles, table

SIZES = [8, 1024, 65536, 921_600, 8 * 1024 * 1024]
# KEEP_LAST(2): a latency-sensitive stream keeps little history. Deeper rings cost nothing in
# protocol but rotate through more slots, so big payloads are copied into colder memory: at
# 921,600 B a ring of depth 10 cycles 9 MB per direction, past this CPU's 2 MB L2.
DEFAULT_DEPTH = 2
TRANSPORTS = ["emos", "mp_queue", "mp_pipe"]
MODES = ["both", "transport", "component"]
METHODS = {
    "pingpong": ("half a round trip (ping-pong)", ipc_pingpong.latency_us),
    "oneway": ("one way, paced sender", ipc_oneway.latency_us),
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="print the machine-readable result")
    parser.add_argument("--plot", metavar="FILE", help="save p50 latency by payload size and transport as a picture (.png, .svg, .pdf)")
    parser.add_argument("--method", choices=list(METHODS), default="pingpong", help="how latency is measured (default: pingpong, half a round trip)")
    parser.add_argument("--sizes", default=",".join(map(str, SIZES)), help="payload sizes in bytes, comma-separated")
    parser.add_argument("--transports", default=",".join(TRANSPORTS), help=f"comma-separated, from {','.join(TRANSPORTS)}")
    parser.add_argument("--messages", type=int, default=400, help="latency samples per size (fewer for large payloads)")
    parser.add_argument("--throughput-seconds", type=float, default=1.0)
    parser.add_argument("--cpus", default=_default_cpus(), help="pin the two ends to these CPUs, 'A,B', or 'none' (default: the first two CPUs this process may use, each end on its own)")
    parser.add_argument("--depth", type=int, default=DEFAULT_DEPTH, help=f"history depth (KEEP_LAST) of the EMOS rings in the transport latency test (default {DEFAULT_DEPTH})")
    parser.add_argument("--peers", metavar="LIST",
                        help=f"compare EMOS with these IPC peers in the same run, comma-separated from {','.join(ipc_peers.PEERS)} "
                             "(ping-pong, interleaved over --rounds; package peers are installed into a benchmark-only "
                             f"environment under ${ipc_peers.ENV_PEER_DIR} or ~/.cache/emos-bench/peers)")
    parser.add_argument("--rounds", type=int, default=3, help="with --peers: rounds, each measuring every transport and size once (default 3)")
    parser.add_argument("--mode", choices=MODES, default="both",
                        help="transport: the rings under a bare event loop, against multiprocessing; component: ping-pong between two "
                             "supervised BaseComponents with default QoS (what recipes get); both (default)")


def _samples_for(size: int, wanted: int) -> int:
    return max(40, min(wanted, int(wanted * 65536 / max(size, 65536))))


def measure(transports: list[str], sizes: list[int], messages: int, seconds: float, method: str = "pingpong", progress: bool = True, depth: int = DEFAULT_DEPTH) -> list[dict[str, Any]]:
    """One row per (size, transport): latency by ``method``, throughput one way."""
    latency_us = METHODS[method][1]
    unit = "round trips" if method == "pingpong" else "msgs"
    results = []
    for size in sizes:
        for transport in transports:
            count = _samples_for(size, messages)
            if progress:
                print(f"  {transport:>8} {size:>9} B: latency ({count} {unit})...", end="", flush=True)
            with ipc_common.placed():
                try:
                    lat, mismatches, error = latency_us(transport, size, count, depth=depth), 0, None
                except ipc_pingpong.SequenceMismatch as exc:  # a result, and an error: reported, not hidden
                    lat, mismatches, error = [], exc.count, str(exc)
                got, span, dropped = ipc_oneway.throughput(transport, size, seconds)
            p = percentiles(lat)
            rate = got / span if span > 0 else float("nan")
            if progress:
                print(f" p50 {p['p50']:.1f} us, p99 {p['p99']:.1f} us; {rate:,.0f} msg/s" + (f"; ERROR {error}" if error else ""), flush=True)
            row = {"transport": transport, "payload_bytes": size, "p50_us": round(p["p50"], 2), "p99_us": round(p["p99"], 2), "msgs_per_s": round(rate, 1), "dropped": dropped, "seq_mismatches": mismatches}
            if error:
                row["error"] = error
            results.append(row)
    return results


def _parse_list(text: str) -> list[str]:
    return [item.strip() for item in text.split(",") if item.strip()]


def _default_cpus() -> str:
    """The first two CPUs this process may run on (cgroups and taskset restrict them), or 'none'."""
    allowed = sorted(os.sched_getaffinity(0))
    return f"{allowed[0]},{allowed[1]}" if len(allowed) >= 2 else "none"


def _parse_cpus(text: str) -> tuple[int, int] | None | str:
    """``(A, B)``, ``None`` for 'none', or an error message."""
    if text.strip().lower() == "none":
        return None
    try:
        a, b = (int(part) for part in text.split(","))
    except ValueError:
        return f"--cpus must be 'A,B' (two CPU numbers) or 'none', got {text!r}"
    allowed = os.sched_getaffinity(0)
    if a not in allowed or b not in allowed:
        return f"--cpus {text}: this process may run on CPUs {sorted(allowed)} only"
    return a, b


def _usage_error(message: str) -> int:
    print(f"emos bench ipc: {message}", file=sys.stderr)
    return 2


def run(args: argparse.Namespace) -> int:
    try:
        sizes = [int(s) for s in _parse_list(args.sizes)]
    except ValueError:
        return _usage_error(f"--sizes must be comma-separated byte counts, got {args.sizes!r}")
    if not sizes or min(sizes) <= 0:
        return _usage_error(f"--sizes must be positive byte counts, got {args.sizes!r}")
    transports = _parse_list(args.transports)
    bad = [t for t in transports if t not in TRANSPORTS]
    if bad or not transports:
        return _usage_error(f"unknown transport(s) {bad}; choose from {TRANSPORTS}")
    if args.messages < 1:
        return _usage_error(f"--messages must be at least 1, got {args.messages}")
    if not args.throughput_seconds > 0:
        return _usage_error(f"--throughput-seconds must be positive, got {args.throughput_seconds}")
    if args.depth < 2:
        return _usage_error(f"--depth must be at least 2 (a ring keeps at least two messages), got {args.depth}")
    placement = _parse_cpus(args.cpus)
    if isinstance(placement, str):
        return _usage_error(placement)
    ipc_common.PLACEMENT = placement
    if args.peers is not None:
        return _run_peers(args, sizes, placement)
    label = METHODS[args.method][0]
    where = "unpinned" if placement is None else f"pinned to CPUs {placement[0]} and {placement[1]}"
    doc: dict[str, Any] = {"mode": args.mode, "method": args.method, "cpus": None if placement is None else list(placement), "emos_depth": args.depth, "emos_wake_spin_us": wake_spin_setting()}
    failed = False
    from emos.tools.plotting import check_plot_argument, save_lines

    check_plot_argument(args.plot)
    if args.mode in ("both", "transport"):
        if not args.json:
            print(f"emos bench ipc, transport mode, on {os.cpu_count()} cores ({where}): payloads {sizes}; latency {label}; EMOS depth {args.depth}, wake spin {wake_spin_setting():g} us")
        results = measure(transports, sizes, args.messages, args.throughput_seconds, args.method, progress=not args.json, depth=args.depth)
        doc["results"] = results
        failed = any("error" in r for r in results)
        if args.plot:
            save_lines(args.plot, f"emos bench ipc: {label}", "payload (bytes)", "p50 latency (us)",
                       {t: ([r["payload_bytes"] for r in results if r["transport"] == t], [r["p50_us"] for r in results if r["transport"] == t])
                        for t in dict.fromkeys(r["transport"] for r in results)}, log=True)
        if not args.json:
            _print_transport(results, sizes, label, args.method)
    if args.mode in ("both", "component"):
        if not args.json:
            print(f"\nemos bench ipc, component mode ({where}): two supervised BaseComponents, default QoS (depth {ipc_component.qos_depth()}), half round trips...", flush=True)
        rows, error = ipc_component.latency(sizes, args.messages, _samples_for)
        doc["component"] = {"qos_depth": ipc_component.qos_depth(), "results": rows, "error": error}
        failed = failed or error is not None
        if not args.json:
            print(table(rows, [("transport", "path", ""), ("payload_bytes", "bytes", ",d"), ("p50_us", "p50 us", ".1f"), ("p99_us", "p99 us", ".1f"), ("round_trips", "samples", "d"), ("seq_mismatches", "seq errors", "d")]))
            if error:
                print(f"ERROR: {error}", file=sys.stderr)
    if args.json:
        print(json.dumps(doc))
    return 1 if failed else 0


def _print_transport(results: list[dict[str, Any]], sizes: list[int], label: str, method: str) -> None:
    print()
    print(f"latency: {label} (--method {method}); throughput: one way, sender flat out")
    print(table(results, [("transport", "transport", ""), ("payload_bytes", "bytes", ",d"), ("p50_us", "p50 us", ".1f"), ("p99_us", "p99 us", ".1f"), ("msgs_per_s", "msg/s", ",.0f")]))
    by = {(r["transport"], r["payload_bytes"]): r for r in results}
    print()
    for size in sizes:
        e, p = by.get(("emos", size)), by.get(("mp_pipe", size))
        if e and p and e["p50_us"] > 0:
            print(f"  {size:>9} B: pipe p50 / emos p50 = {p['p50_us'] / e['p50_us']:.1f}x")


def _run_peers(args: argparse.Namespace, sizes: list[int], placement: tuple[int, int] | None) -> int:
    """``--peers``: EMOS and the peers, half round trips, interleaved over ``--rounds``."""
    peers = [p for p in _parse_list(args.peers) if p != "emos"]
    problem = ipc_peers.check_peers(peers)
    if problem or not peers:
        return _usage_error(problem or f"--peers needs at least one of {','.join(ipc_peers.PEERS)}")
    if args.rounds < 1:
        return _usage_error(f"--rounds must be at least 1, got {args.rounds}")
    if args.method != "pingpong":
        return _usage_error("--peers measures half round trips only (--method pingpong)")
    say = None if args.json else (lambda line: print(line, flush=True))
    try:
        ipc_peers.prepare(peers, say or (lambda line: print(line, file=sys.stderr, flush=True)))
    except ipc_peers.PeerUnavailable as exc:
        print(f"emos bench ipc: {exc}", file=sys.stderr)
        return 2
    where = "unpinned" if placement is None else f"pinned to CPUs {placement[0]} and {placement[1]}"
    if say:
        say(f"emos bench ipc --peers: EMOS rings (depth {args.depth}, wake spin {wake_spin_setting():g} us) against {', '.join(peers)}; "
            f"half round trips, {args.rounds} interleaved round(s), {where}; payloads {sizes}")
    result = ipc_peers.run_rounds(["emos", *peers], sizes, args.rounds, args.messages, _samples_for, args.depth, say)
    doc: dict[str, Any] = {"mode": "peers", "method": "pingpong", "cpus": None if placement is None else list(placement),
                           "emos_depth": args.depth, "emos_wake_spin_us": wake_spin_setting(), **result}
    if args.json:
        print(json.dumps(doc))
    else:
        print()
        print(f"p50 and p99: median over {args.rounds} round(s); spread: max / min over rounds; load averages {result['loads']}")
        print(table(result["results"], [("transport", "transport", ""), ("payload_bytes", "bytes", ",d"), ("p50_us", "p50 us", ".1f"),
                                         ("p50_min_us", "p50 min", ".1f"), ("p50_max_us", "p50 max", ".1f"), ("p50_spread", "p50 spread", ".2f"),
                                         ("p99_us", "p99 us", ".1f"), ("p99_spread", "p99 spread", ".2f")]))
        for transport, about in dict.fromkeys((r["transport"], r.get("about")) for r in result["results"]):
            print(f"  {transport}: {about}")  # what each row measures (the JSON's "about")
    return 1 if any("errors" in row for row in result["results"]) else 0
