"""``emos bench ipc``, ping-pong: latency as half a round trip between two processes.

The initiator sends a payload, an echo process sends the same bytes back, and the initiator
takes the time once the reply is usable as a numpy array; a sample is half that round trip.
Both processes are busy or blocked in the transport the whole time, so no CPU idles long between
messages: this measures the transport, not the hypervisor waking an idle vCPU.
"""
from __future__ import annotations

import asyncio
import queue
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np

from emos.errors import EmosError
from emos.tools.bench.ipc_common import FORK, random_payload, remove_topic, start_child, stop_child, wait_ready

SUBSCRIBER_QUEUE = 64
# Generous bounds that only a hung or dead peer reaches.
_READY_TIMEOUT_S = 30.0
_STOP_TIMEOUT_S = 10.0


def warmup_round_trips(count: int) -> int:
    """Round trips run and discarded before sampling: rings grow, pages fault in, caches warm."""
    return max(3, min(20, count // 4))


def _round_trip_timeout(size: int, round_trips: int) -> float:
    return 30.0 + round_trips * (0.01 + size / 2e8)


SEQ_BYTES = 8


class SequenceMismatch(EmosError, RuntimeError):
    """Replies that did not carry the sequence number of the ping in flight."""

    def __init__(self, transport: str, size: int, count: int):
        super().__init__(f"{transport} at {size} B: {count} repl(ies) carried the wrong sequence number")
        self.count = count


def _stamp(payload: np.ndarray, seq: int) -> None:
    """Write ``seq`` into the first 8 bytes of the payload (payloads under 8 B carry what fits)."""
    n = min(SEQ_BYTES, payload.nbytes)
    payload[:n] = np.frombuffer(seq.to_bytes(SEQ_BYTES, "little")[:n], np.uint8)


def _seq_matches(reply: np.ndarray, payload: np.ndarray) -> bool:
    n = min(SEQ_BYTES, payload.nbytes)
    return reply.nbytes == payload.nbytes and bytes(reply[:n]) == bytes(payload[:n])


def _check_echo(data: np.ndarray, payload: np.ndarray, first: bool) -> None:
    if data.nbytes != payload.nbytes:
        raise RuntimeError(f"echo returned {data.nbytes} B for a {payload.nbytes} B payload")
    # The full comparison once per run (after the clock stopped): proves the echo path is real.
    if first and not np.array_equal(data, payload):
        raise RuntimeError(f"echo of a {payload.nbytes} B payload came back with different bytes")


# ------------------------------------------------------------------ EMOS
@contextmanager
def _emos_node(ctx: Any, listen: str, speak: str, publisher_id: str, depth: int) -> Iterator[tuple[Any, Any, Any, Any]]:
    """What one side of the ping-pong owns, as a component does: its own uvloop event loop, a
    wake-up FIFO, a subscriber on ``listen`` and a named publisher on ``speak``; all closed on
    every path."""
    import uvloop

    from emos.core.node import wake_spin_setting
    from emos.msgs import UInt8MultiArray
    from emos.transport.pubsub import Publisher, Subscriber
    from emos.transport.waker import Waker

    loop = uvloop.new_event_loop()
    asyncio.set_event_loop(loop)
    waker = sub = pub = None
    try:
        waker = Waker(ctx, spin_us=wake_spin_setting())  # as a component's node does
        sub = Subscriber(ctx, listen, UInt8MultiArray, waker=waker, queue_size=SUBSCRIBER_QUEUE)
        pub = Publisher(ctx, speak, UInt8MultiArray, publisher_id=publisher_id, depth=depth)
        yield loop, waker, sub, pub
    finally:
        if waker is not None and waker.fd >= 0:
            loop.remove_reader(waker.fd)
        for part in (sub, pub, waker):
            if part is not None:
                part.close()
        asyncio.set_event_loop(None)
        loop.close()


def _emos_echo(ping: str, pong: str, ready: Any, timeout: float, depth: int) -> None:
    """Echo process: decode every ping (arrays become views, as in a component) and publish the
    decoded message itself on ``pong``. An empty array is the stop sentinel."""
    from emos.msgs import UInt8MultiArray, codec
    from emos.transport.context import current

    with _emos_node(current(), ping, pong, "bench-echo", depth) as (loop, waker, sub, pub):
        done = loop.create_future()

        def handle() -> None:
            if done.done():
                return
            try:
                # ``raw`` goes only to decode: the transport decides what buffer it hands out.
                for _, raw, _ in sub.take_raw():
                    msg = codec.decode(UInt8MultiArray, raw)
                    if msg.data.size == 0:
                        done.set_result(None)
                        return
                    pub.publish(msg)
            except Exception as exc:  # a reader callback's exception would only be logged
                if not done.done():
                    done.set_exception(exc)

        # A node's wake-up path: drain, handle, linger for more (waker.serve).
        loop.add_reader(waker.fd, waker.serve, handle, sub.has_news)
        ready.send("ready")
        ready.close()
        loop.run_until_complete(asyncio.wait_for(done, timeout))


def _emos_half_rtts(size: int, count: int, depth: int) -> list[float]:
    from emos.msgs import UInt8MultiArray, codec
    from emos.transport.context import current

    ctx = current()  # BEFORE forking: the echo inherits this run and sees its topics
    ping, pong = f"/bench/ipc_{size}_ping", f"/bench/ipc_{size}_pong"
    total = warmup_round_trips(count) + count
    timeout = _round_trip_timeout(size, total)
    ready_r, ready_w = FORK.Pipe(duplex=False)
    proc = start_child(_emos_echo, (ping, pong, ready_w, timeout + _READY_TIMEOUT_S, depth), "emos:bench-echo")
    ready_w.close()
    try:
        wait_ready(ready_r, proc, _READY_TIMEOUT_S)
        payload = random_payload(size)
        msg = UInt8MultiArray(data=payload)
        with _emos_node(ctx, pong, ping, "bench-initiator", depth) as (loop, waker, sub, pub):
            rtts_ns: list[int] = []
            done = loop.create_future()
            sent_at = 0  # 0: no ping in flight
            seq = mismatches = 0

            def send() -> None:
                nonlocal sent_at, seq
                seq += 1
                _stamp(payload, seq)  # every ping carries its number; the reply must carry it back
                sent_at = time.perf_counter_ns()
                pub.publish(msg)

            def handle() -> None:
                nonlocal sent_at
                if done.done():
                    return
                nonlocal mismatches
                try:
                    for _, raw, _ in sub.take_raw():
                        echo = codec.decode(UInt8MultiArray, raw)
                        now = time.perf_counter_ns()  # the echo is decoded and usable
                        if sent_at == 0:
                            raise RuntimeError(f"topic {pong}: a reply arrived with no ping in flight")
                        if not _seq_matches(echo.data, payload):
                            mismatches += 1  # stale or duplicated: not the reply to this ping
                            continue
                        rtts_ns.append(now - sent_at)
                        sent_at = 0
                        _check_echo(echo.data, payload, first=len(rtts_ns) == 1)
                        if len(rtts_ns) >= total:
                            done.set_result(None)
                            return
                        send()
                except Exception as exc:
                    if not done.done():
                        done.set_exception(exc)

            loop.add_reader(waker.fd, waker.serve, handle, sub.has_news)
            try:
                loop.call_soon(send)
                loop.run_until_complete(asyncio.wait_for(done, timeout))
            except TimeoutError:
                raise RuntimeError(f"EMOS ping-pong at {size} B: {len(rtts_ns)} of {total} round trips in {timeout:.0f} s") from None
            finally:
                pub.publish(UInt8MultiArray(data=np.zeros(0, np.uint8)))  # stop the echo
        exit_code = stop_child(proc, _STOP_TIMEOUT_S)
        if exit_code != 0:
            raise RuntimeError(f"EMOS echo process exited with code {exit_code}")
    finally:
        stop_child(proc, _STOP_TIMEOUT_S)  # at once if already stopped
        ready_r.close()
        remove_topic(ctx, ping)
        remove_topic(ctx, pong)
    if mismatches:
        raise SequenceMismatch("emos", size, mismatches)
    return [ns / 2e3 for ns in rtts_ns[total - count :]]


# ------------------------------------------------------------------ multiprocessing
def _pipe_echo(conn: Any) -> None:
    while (item := conn.recv()) is not None:
        conn.send(item)


def _queue_echo(there: Any, back: Any) -> None:
    while (item := there.get()) is not None:
        back.put(item)
    back.close()
    back.join_thread()


def _pipe_half_rtts(size: int, count: int) -> list[float]:
    """One duplex ``multiprocessing.Pipe``; the echo sends back what it received."""
    payload_arr = random_payload(size)
    total = warmup_round_trips(count) + count
    mine, theirs = FORK.Pipe(duplex=True)
    proc = start_child(_pipe_echo, (theirs,), "emos:bench-echo")
    theirs.close()  # so a dead echo is an EOFError here, not a hang
    rtts_ns: list[int] = []
    mismatches = 0
    try:
        for i in range(total):
            _stamp(payload_arr, i + 1)
            payload = payload_arr.tobytes()  # before the clock starts
            start = time.perf_counter_ns()
            mine.send(payload)
            reply = np.frombuffer(mine.recv(), dtype=np.uint8)
            rtts_ns.append(time.perf_counter_ns() - start)
            mismatches += not _seq_matches(reply, payload_arr)
            _check_echo(reply, payload_arr, first=i == 0)
        mine.send(None)
    except EOFError:
        raise RuntimeError(f"Pipe echo process died (exit code {proc.exitcode})") from None
    finally:
        exit_code = stop_child(proc, _STOP_TIMEOUT_S)
        mine.close()
    if exit_code != 0:
        raise RuntimeError(f"Pipe echo process exited with code {exit_code}")
    if mismatches:
        raise SequenceMismatch("mp_pipe", size, mismatches)
    return [ns / 2e3 for ns in rtts_ns[total - count :]]


def _queue_half_rtts(size: int, count: int) -> list[float]:
    """Two ``multiprocessing.Queue``s, there and back."""
    payload_arr = random_payload(size)
    total = warmup_round_trips(count) + count
    timeout = _round_trip_timeout(size, 1)
    there, back = FORK.Queue(), FORK.Queue()
    proc = start_child(_queue_echo, (there, back), "emos:bench-echo")
    rtts_ns: list[int] = []
    exit_code: int | None = None
    mismatches = 0
    try:
        for i in range(total):
            _stamp(payload_arr, i + 1)
            payload = payload_arr.tobytes()  # before the clock starts
            start = time.perf_counter_ns()
            there.put(payload)
            try:
                raw = back.get(timeout=timeout)
            except queue.Empty as exc:  # the echo is dead or hung
                raise RuntimeError(f"Queue echo gave no reply in {timeout:.0f} s (exit code {proc.exitcode})") from exc
            reply = np.frombuffer(raw, dtype=np.uint8)
            rtts_ns.append(time.perf_counter_ns() - start)
            mismatches += not _seq_matches(reply, payload_arr)
            _check_echo(reply, payload_arr, first=i == 0)
        there.put(None)
    finally:
        exit_code = stop_child(proc, _STOP_TIMEOUT_S)
        for q in (there, back):
            if exit_code != 0:
                q.cancel_join_thread()  # nobody will read what is left: do not wait to flush it
            # No thread may outlive a measurement: the next one forks.
            q.close()
            q.join_thread()
    if exit_code != 0:
        raise RuntimeError(f"Queue echo process exited with code {exit_code}")
    if mismatches:
        raise SequenceMismatch("mp_queue", size, mismatches)
    return [ns / 2e3 for ns in rtts_ns[total - count :]]


def latency_us(transport: str, size: int, count: int, depth: int = 2) -> list[float]:
    """``count`` half round trips in microseconds, after :func:`warmup_round_trips` discarded."""
    if transport == "emos":
        return _emos_half_rtts(size, count, depth)
    if transport == "mp_pipe":
        return _pipe_half_rtts(size, count)
    return _queue_half_rtts(size, count)
