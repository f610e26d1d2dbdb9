"""``emos bench net``: topic latency and throughput between two runs over Zenoh, EMOS's Zenoh
transport against raw ``eclipse-zenoh`` pub/sub carrying the same bytes, measured the same way
in the same run.

Two processes, each with its own Zenoh session (peer mode, each listening on a loopback port
and connecting to the other's, no multicast scouting, Zenoh's shared memory off: TCP over
127.0.0.1, as between hosts), and no shared memory between them. Both transports use the
same hand-off a node uses: Zenoh's callback thread queues the sample and writes one byte to a
pipe, the main thread wakes on the pipe, takes the sample, and answers.

* ``emos-zenoh``: :class:`ZenohPublisher` / :class:`ZenohSubscriber` with a ``UInt8MultiArray``
  of ``payload_bytes``: encode, frame, put (from 64 KiB, the array as the payload and the header
  in the attachment); on the other side check the frame and decode it on Zenoh's thread, take
  the message on the main thread (``take()``; the array is a view), and the echo re-publishes
  the decoded message.
  The pinging side's message is a view of the same ``bytes`` object the raw peer puts, so both
  start from the same bytes (an ``ndarray`` of its own would cost EMOS one copy per send, as
  ``arr.tobytes()`` would cost a raw Zenoh program).
* ``zenoh``: ``session.declare_publisher(...).put(bytes)`` and a callback subscriber; the echo
  puts the received bytes back.

Latency: half a ping-pong round trip (``time.perf_counter_ns`` on the sender). Throughput:
payload bytes per second of those round trips (both directions), which is what a request/
reply stream of that size sustains. The two transports alternate size by size, so machine load
hits both alike.
"""
from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import queue
import select
import socket
import sys
import tempfile
import time
import uuid
from typing import Any

import numpy as np

from emos.tools.bench.common import percentiles, table

SIZES = [8, 921_600, 8 * 1024 * 1024]
TRANSPORTS = ["emos-zenoh", "zenoh"]


MODES = ["both", "transport", "component"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="print the machine-readable result")
    parser.add_argument("--mode", choices=MODES, default="both",
                        help="transport: EMOS's Zenoh publisher and subscriber under a bare loop, against raw Zenoh; component: "
                             "ping-pong between components of two real runs over Zenoh (the raw figure: the transport mode's, same invocation)")
    parser.add_argument("--sizes", default=",".join(map(str, SIZES)), help="payload sizes in bytes, comma-separated")
    parser.add_argument("--messages", type=int, default=300, help="round trips per size and transport (fewer for large payloads)")
    parser.add_argument("--rounds", type=int, default=3, help="alternations of the two transports per size (samples are pooled)")
    parser.add_argument("--tls", action="store_true",
                        help="transport mode: also measure both transports over mutual TLS with access control (a secure run's "
                             "configuration, certificates from a fresh keystore), alternating with plain TCP in the same run")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _config_file(folder: str, name: str, listen: int, connect: int) -> str:
    path = os.path.join(folder, f"{name}.json5")
    with open(path, "w") as f:
        json.dump({
            "mode": "peer",
            "listen": {"endpoints": [f"tcp/127.0.0.1:{listen}"]},
            "connect": {"endpoints": [f"tcp/127.0.0.1:{connect}"]},
            "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
            # As between hosts: no shared-memory shortcut between two processes of this one
            # (EMOS's default too, see zenoh_config.load_config; said here so that it holds
            # whatever that default becomes).
            "transport": {"shared_memory": {"enabled": False}},
        }, f)
    return path


class _Inbox:
    """A queue filled on Zenoh's threads, with a pipe the main thread blocks on."""

    def __init__(self) -> None:
        self.items: queue.SimpleQueue[Any] = queue.SimpleQueue()
        self.rfd, self.wfd = os.pipe()
        os.set_blocking(self.wfd, False)

    def notify(self) -> None:
        try:
            os.write(self.wfd, b"\x01")
        except BlockingIOError:
            pass

    def put(self, item: Any) -> None:
        self.items.put(item)
        self.notify()

    def wait(self, timeout: float) -> bool:
        ready, _, _ = select.select([self.rfd], [], [], timeout)
        if ready:
            os.read(self.rfd, 4096)
        return bool(ready)


TLS = "+tls"  # suffix of a transport measured over the TLS configuration pair


def _tls_config_pair(folder: str) -> tuple[str, str]:
    """Configuration files of a pinging and an echoing end over mutual TLS with access control,
    as ``emos security policy`` writes them (TLS only, deny by default), with certificates of a
    fresh keystore: what ``emos run --secure`` costs."""
    from emos.security.keystore import create_identity, create_keystore
    from emos.security.policy import tls_config

    keys = os.path.join(folder, "keys")
    create_keystore(keys)
    ports = {"ping": _free_port(), "pong": _free_port()}
    acl = {"enabled": True, "default_permission": "deny",
           "rules": [{"id": "bench", "permission": "allow", "messages": ["put", "declare_subscriber", "liveliness_token"],
                      "flows": ["ingress", "egress"], "key_exprs": ["emos/**", "rawbench/**"]}],
           "subjects": [{"id": "peers", "cert_common_names": ["ping", "pong"]}], "policies": [{"id": "bench", "rules": ["bench"], "subjects": ["peers"]}]}
    paths = []
    for name, other in (("ping", "pong"), ("pong", "ping")):
        create_identity(keys, name, hosts=["127.0.0.1"])
        path = os.path.join(folder, f"{name}-tls.json5")
        with open(path, "w") as f:
            json.dump({
                "mode": "peer", "listen": {"endpoints": [f"tls/127.0.0.1:{ports[name]}"]}, "connect": {"endpoints": [f"tls/127.0.0.1:{ports[other]}"]},
                "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
                "transport": {"shared_memory": {"enabled": False}, "link": {"protocols": ["tls"], "tls": tls_config(keys, name)}},
                "access_control": acl,
            }, f)
        paths.append(path)
    return paths[0], paths[1]


class _End:
    """One side of one transport: ``send(payload)``, ``take() -> payloads``, and its inbox."""

    def __init__(self, config: str, group: str, transport: str, side: str):
        transport = transport.removesuffix(TLS)
        from emos.msgs import UInt8MultiArray
        from emos.transport import zenoh_net

        self.inbox = _Inbox()
        # EMOS's ZenohPublisher/ZenohSubscriber, or (raw-zenoh) the session's own publisher/subscriber.
        self._pub: Any
        self._sub: Any
        out_topic, in_topic = ("/bench/ping", "/bench/pong") if side == "ping" else ("/bench/pong", "/bench/ping")
        if transport == "emos-zenoh":
            self._pub = zenoh_net.ZenohPublisher(out_topic, UInt8MultiArray, publisher_id=side, config_path=config, group=group)
            self._sub = zenoh_net.ZenohSubscriber(in_topic, UInt8MultiArray, notify=self.inbox.notify, queue_size=64, config_path=config, group=group)
            self.send, self.take = self._pub.publish, self._sub.take
            return
        zenoh = zenoh_net._zenoh()
        sess = zenoh_net.session(config)
        self._pub = sess.declare_publisher(f"rawbench/{group}{out_topic}", congestion_control=zenoh.CongestionControl.DROP)
        self._sub = sess.declare_subscriber(f"rawbench/{group}{in_topic}", lambda sample: self.inbox.put(sample.payload.to_bytes()))
        self.send, self.take = self._pub.put, self._take_raw

    def _take_raw(self) -> list:
        got = []
        while True:
            try:
                got.append(self.inbox.items.get_nowait())
            except queue.Empty:
                return got


def _echo_main(config: str, group: str, ready: Any, tls_config: str | None = None) -> None:
    """The other run: echo every message of both transports (and over TLS: ``tls_config``) until killed."""
    ends = [_End(config, group, t, "pong") for t in TRANSPORTS] + [_End(tls_config, group, t, "pong") for t in TRANSPORTS if tls_config]
    by_fd = {end.inbox.rfd: end for end in ends}
    ready.set()
    while True:
        readable, _, _ = select.select(list(by_fd), [], [], 1.0)
        for fd in readable:
            os.read(fd, 4096)
            end = by_fd[fd]
            for msg in end.take():
                end.send(msg)


def _round_trips(end: _End, payload: Any, count: int, timeout: float = 2.0) -> tuple[list[float], int]:
    """Half round trips in microseconds, and how many got no echo within ``timeout`` (a full
    Zenoh queue drops rather than blocks). The first few (warm-up) are not counted."""
    samples, lost = [], 0
    clock = time.perf_counter_ns
    for i in range(count + 3):
        t0 = clock()
        end.send(payload)
        got: list = []
        deadline = time.monotonic() + timeout
        while not got:
            if not end.inbox.wait(max(deadline - time.monotonic(), 0.0)):
                break
            got = end.take()
        t1 = clock()
        if not got:
            lost += 1
            time.sleep(0.2)
            end.take()  # a late echo must not answer the next ping
            if lost > max(count // 4, 3):
                raise TimeoutError(f"{lost} of {i + 1} messages got no echo within {timeout} s")
        elif i >= 3:
            samples.append((t1 - t0) / 2000.0)
    return samples, lost


def _messages_for(size: int, messages: int) -> int:
    if size >= 4 * 1024 * 1024:
        return max(messages // 10, 10)
    if size >= 512 * 1024:
        return max(messages // 3, 20)
    return messages


def _config_pair(folder: str) -> tuple[str, str]:
    """Zenoh configuration files of a pinging and an echoing end that reach each other."""
    port_ping, port_pong = _free_port(), _free_port()
    return _config_file(folder, "ping", port_ping, port_pong), _config_file(folder, "pong", port_pong, port_ping)


def measure(sizes: list[int], messages: int, rounds: int, transports: list[str] = TRANSPORTS, tls: bool = False) -> list[dict[str, Any]]:
    """The transport mode: rows for each of ``transports`` and size (and each over TLS: ``tls``)."""
    group = f"bench{uuid.uuid4().hex[:8]}"
    with tempfile.TemporaryDirectory(prefix="emos-bench-net-") as folder:
        tls_pair = _tls_config_pair(folder) if tls else None
        if tls:
            transports = [*transports, *(t + TLS for t in transports)]
        return _measure(sizes, messages, rounds, transports, group, *_config_pair(folder), tls_pair=tls_pair)


def _measure(sizes: list[int], messages: int, rounds: int, transports: list[str], group: str, ping_conf: str, pong_conf: str,
             tls_pair: tuple[str, str] | None = None) -> list[dict[str, Any]]:
    from emos.msgs import UInt8MultiArray
    from emos.transport import zenoh_net

    spawn = mp.get_context("spawn")  # a fresh interpreter: no Zenoh session or thread inherited
    ready = spawn.Event()
    echo = spawn.Process(target=_echo_main, args=(pong_conf, group, ready, tls_pair[1] if tls_pair else None), name="emos-bench-net-echo", daemon=True)
    echo.start()
    results = []
    try:
        if not ready.wait(60):
            raise RuntimeError("the echo process did not come up within 60 s")
        ends = {t: _End(tls_pair[0] if tls_pair and t.endswith(TLS) else ping_conf, group, t, "ping") for t in transports}
        time.sleep(0.5)  # let the two sessions connect and match subscriptions
        for size in sizes:
            data = np.random.default_rng(size).integers(0, 256, size, dtype=np.uint8)
            raw = data.tobytes()
            # Both carry the same bytes object: the EMOS message's array is a view of it.
            payloads = {"emos-zenoh": UInt8MultiArray(data=np.frombuffer(raw, np.uint8)), "zenoh": raw}
            payloads.update({t + TLS: payloads[t] for t in list(payloads)})
            samples: dict[str, list[float]] = {t: [] for t in transports}
            lost = {t: 0 for t in transports}
            count = max(_messages_for(size, messages) // rounds, 5)
            for _ in range(rounds):
                for t in transports:
                    got, missing = _round_trips(ends[t], payloads[t], count)
                    samples[t] += got
                    lost[t] += missing
            for t in transports:
                pct = percentiles(samples[t], (50, 95))
                mean_rtt_s = 2 * sum(samples[t]) / len(samples[t]) / 1e6
                results.append({
                    "transport": t, "payload_bytes": size, "p50_us": round(pct["p50"], 1), "p95_us": round(pct["p95"], 1),
                    "samples": len(samples[t]), "lost": lost[t], "mb_per_s": round(2 * size / mean_rtt_s / 1e6, 2),
                })
    finally:
        echo.kill()
        echo.join(5)
        zenoh_net.close_sessions()
    return results


def run(args: argparse.Namespace) -> int:
    try:
        sizes = [int(s) for s in args.sizes.split(",") if s.strip()]
    except ValueError:
        print(f"emos bench net: --sizes must be byte counts separated by ',', got {args.sizes!r}", file=sys.stderr)
        return 2
    if not sizes or min(sizes) < 1 or args.messages < 1 or args.rounds < 1:
        print("emos bench net: sizes, --messages and --rounds must be >= 1", file=sys.stderr)
        return 2
    with_transport, with_component = args.mode in ("both", "transport"), args.mode in ("both", "component")
    # The component mode's raw figure is the transport mode's raw Zenoh, from this invocation.
    results = measure(sizes, args.messages, args.rounds, TRANSPORTS if with_transport else ["zenoh"], tls=args.tls and with_transport)
    raw_p50 = {r["payload_bytes"]: r["p50_us"] for r in results if r["transport"] == "zenoh"}
    p50 = {(r["transport"], r["payload_bytes"]): r["p50_us"] for r in results}
    for r in results:
        if r["transport"] == "emos-zenoh":
            r["overhead_p50_pct"] = _overhead(r["p50_us"], raw_p50[r["payload_bytes"]])
        if r["transport"] == "emos-zenoh" + TLS:
            r["overhead_p50_pct"] = _overhead(r["p50_us"], p50[("zenoh" + TLS, r["payload_bytes"])])
        if r["transport"].endswith(TLS):  # the same transport over plain TCP, same run
            r["tls_overhead_p50_pct"] = _overhead(r["p50_us"], p50[(r["transport"].removesuffix(TLS), r["payload_bytes"])])
    doc: dict[str, Any] = {"method": "pingpong over Zenoh, TCP on 127.0.0.1, two processes", "results": results}
    if with_component:
        from emos.tools.bench import net_component

        if not args.json:
            print("emos bench net, component mode: Ping and Echo components in two runs over Zenoh...", file=sys.stderr, flush=True)
        with tempfile.TemporaryDirectory(prefix="emos-bench-net-") as folder:
            rows, error = net_component.latency(sizes, lambda size: _messages_for(size, args.messages), _config_pair(folder), f"bench{uuid.uuid4().hex[:8]}")
        for r in rows:
            r["overhead_p50_pct"] = _overhead(r["p50_us"], raw_p50[r["payload_bytes"]])
        doc["component"] = {"method": "pingpong between components of two runs over Zenoh (TCP on 127.0.0.1); overhead against the raw Zenoh rows",
                            "results": rows, "error": error}
    if args.json:
        print(json.dumps(doc))
        return 0 if not with_component or doc["component"]["error"] is None else 1
    columns = [("transport", "transport", "s"), ("payload_bytes", "bytes", "d"), ("p50_us", "p50 us", ".1f"),
               ("p95_us", "p95 us", ".1f"), ("overhead_p50_pct", "EMOS overhead %", ".1f")]
    extra = [("tls_overhead_p50_pct", "TLS overhead %", ".1f")] if args.tls else []
    print(table(results, columns[:4] + [("mb_per_s", "MB/s", ".1f"), columns[4], *extra]))
    if with_component:
        print()
        print(table(doc["component"]["results"], columns))
        if doc["component"]["error"]:
            print(f"component mode: {doc['component']['error']}", file=sys.stderr)
            return 1
    return 0


def _overhead(p50_us: float, raw_p50_us: float) -> float:
    return round(100.0 * (p50_us - raw_p50_us) / raw_p50_us, 1)
