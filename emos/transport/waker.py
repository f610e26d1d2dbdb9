"""Wake-ups across processes through named FIFOs an event loop can wait on.

Each subscribing node owns one FIFO in the run directory, named by a random token. Publishers
write one byte to the FIFO of every registered token after each message; the node's event loop
watches the FIFO's file descriptor (``loop.add_reader``), drains it, and polls its rings.
A publisher that appears or goes away writes ``ANNOUNCE`` instead of ``MESSAGE``: subscribers
then look for new rings, which otherwise they need not do on every wake-up.
A FIFO is a plain file descriptor (unlike a futex), works between unrelated processes (unlike an
eventfd, which must be inherited), and lives in the run's mode-0700 directory.

Spin, then park. Waking a sleeping process costs the publisher a system call that, on a
virtual machine, also interrupts a halted CPU (10-20 us here), and the woken side pays a
scheduler wake-up and a read. So after handling a wake-up a node may *linger*: spin for up to
``spin_us`` checking its rings, with a flag in a small shared page saying so; publishers that
see the flag skip the FIFO. Bursts and request-reply exchanges then cost no system call at all.
When the spin ends the node *parks*: clears the flag, fences, and looks once more, so a message
published while the flag was still visible is never left unannounced. This is the
spin-then-block idle strategy of low-latency messaging (Aeron's backoff, adaptive mutexes);
``spin_us=0`` turns it off.

Robot first. A publisher wakes its subscribers one system call after the other, and on a
machine with few cores the first woken takes the free core. Best-effort readers (the Monitor
evaluating events, the web UI, a recorder) mark their token with :data:`BACKGROUND_BIT`, and
publishers wake them after every other subscriber, so the robot's own components are not queued
behind them. The bit only orders wake-ups: a peer that sets it on its own token harms no one but
itself.
"""
from __future__ import annotations

import errno
import mmap
import os
import secrets
import time
from pathlib import Path
from typing import Callable

from emos.transport.context import RunContext
from emos.transport.fence import full_fence

MESSAGE = b"\x01"
ANNOUNCE = b"\x02"
PARKED, SPINNING = 0, 1  # the state word a Waker shares with the publishers that wake it
DEFAULT_SPIN_US = 100.0  # longer than a request-reply turnaround here; at most this CPU per message
MAX_LINGER_US = 1000.0  # under a flood, return to the event loop this often (timers, RPC, signals)
_STATE_BYTES = 64
BACKGROUND_BIT = 1 << 62  # in a token: wake this reader after the others (module doc)


class Waker:
    """The receiving end: a FIFO this node reads, and the state page publishers consult."""

    def __init__(self, ctx: RunContext, spin_us: float = 0.0, background: bool = False):
        """``background``: publishers wake this reader after the others (module doc)."""
        if spin_us < 0:
            raise ValueError(f"Waker spin_us must be >= 0 microseconds, got {spin_us}")
        token = secrets.randbits(63) | 1
        self.token = token | BACKGROUND_BIT if background else token & ~BACKGROUND_BIT
        self.path = fifo_path(ctx, self.token)
        self.spin_ns = int(spin_us * 1000)
        self.announcements = 0  # how many drains saw a publisher appear or go
        # The state page first: a publisher that can open the FIFO finds it.
        self.state_path = state_path(ctx, self.token)
        fd = os.open(self.state_path, os.O_CREAT | os.O_EXCL | os.O_RDWR, 0o600)
        try:
            try:
                os.ftruncate(fd, _STATE_BYTES)
                self._state_mm = mmap.mmap(fd, _STATE_BYTES)
            finally:
                os.close(fd)
            self._state = memoryview(self._state_mm).cast("Q")
            os.mkfifo(self.path, 0o600)
            # O_RDWR keeps the FIFO open for writing too, so it never reports EOF while idle.
            self.fd = os.open(self.path, os.O_RDWR | os.O_NONBLOCK)
        except BaseException:  # an error or a signal (the CLI turns SIGTERM into SystemExit) half way
            for path in (self.path, self.state_path):
                try:
                    os.unlink(path)
                except FileNotFoundError:
                    pass
            raise

    def fileno(self) -> int:
        return self.fd

    def drain(self) -> int:
        """Read every pending wake-up; returns how many there were."""
        total = 0
        while True:
            try:
                chunk = os.read(self.fd, 65536)
            except BlockingIOError:
                return total
            total += len(chunk)
            if ANNOUNCE in chunk:
                self.announcements += 1
            if len(chunk) < 65536:
                return total

    def poke(self) -> None:
        """Wake ourselves: the event loop calls the reader again."""
        try:
            os.write(self.fd, MESSAGE)
        except BlockingIOError:
            pass  # full: a wake-up is pending anyway

    def serve(self, handle: Callable[[], None], has_news: Callable[[], bool]) -> None:
        """Handle one wake-up: drain, ``handle()``, then linger for more (see module doc).

        ``has_news`` must be cheap (it runs in the spin loop): it says whether any ring this
        node reads has a message ``handle`` has not taken yet.
        """
        self.drain()
        handle()
        if self.spin_ns <= 0:
            return
        clock = time.perf_counter_ns
        yield_cpu = os.sched_yield
        state = self._state
        state[0] = SPINNING
        try:
            # Under a flood, give the event loop its turn now and then (timers, RPC, signals).
            deadline = clock() + max(int(MAX_LINGER_US * 1000), 2 * self.spin_ns)
            while True:
                end = min(clock() + self.spin_ns, deadline)
                while not has_news():
                    if clock() >= end:
                        return
                    # Give the CPU to whoever else can run on it (likely the very publisher we
                    # wait for, when both share a CPU); returns at once when nobody can.
                    yield_cpu()
                handle()
                if clock() >= deadline:
                    return
        finally:
            state[0] = PARKED
            full_fence()  # publishers that still saw SPINNING published before this point...
            if has_news():  # ...so their messages are visible here
                self.poke()

    def close(self) -> None:
        if self.fd >= 0:
            os.close(self.fd)
            self.fd = -1
            for path in (self.path, self.state_path):
                try:
                    os.unlink(path)
                except FileNotFoundError:
                    pass
            self._state.release()
            self._state_mm.close()


def fifo_path(ctx: RunContext, token: int) -> Path:
    return ctx.run_dir / "wake" / f"{token:016x}"


def state_path(ctx: RunContext, token: int) -> Path:
    return ctx.run_dir / "wake" / f"{token:016x}.state"


class WakeSender:
    """The sending end: open FIFOs of the tokens a publisher must wake."""

    def __init__(self, ctx: RunContext):
        self.ctx = ctx
        self.fds: dict[int, int] = {}
        self._states: dict[int, tuple[mmap.mmap, memoryview]] = {}

    def sync(self, tokens: list[int]) -> list[int]:
        """Open FIFOs for new tokens, close those gone; returns tokens whose reader is dead."""
        dead = []
        wanted = set(tokens)
        for token in list(self.fds):
            if token not in wanted:
                self._forget(token)
        for token in wanted - set(self.fds):
            try:
                self.fds[token] = os.open(fifo_path(self.ctx, token), os.O_WRONLY | os.O_NONBLOCK)
            except OSError as exc:
                # ENXIO: no reader has it open; ENOENT: the FIFO is gone. Either way its node died.
                if exc.errno in (errno.ENXIO, errno.ENOENT):
                    dead.append(token)
                    continue
                raise
            self._map_state(token)
        # Foreground readers first (dicts keep insertion order; wake() walks it).
        if any(t & BACKGROUND_BIT for t in self.fds):
            self.fds = dict(sorted(self.fds.items(), key=lambda item: bool(item[0] & BACKGROUND_BIT)))
        return dead

    def _map_state(self, token: int) -> None:
        try:
            fd = os.open(state_path(self.ctx, token), os.O_RDONLY)
        except FileNotFoundError:
            return  # no state page: always write to this FIFO
        try:
            mm = mmap.mmap(fd, _STATE_BYTES, prot=mmap.PROT_READ)
        except (OSError, ValueError):
            return
        finally:
            os.close(fd)
        self._states[token] = (mm, memoryview(mm).cast("Q"))

    def _forget(self, token: int) -> None:
        os.close(self.fds.pop(token))
        state = self._states.pop(token, None)
        if state is not None:
            state[1].release()
            state[0].close()

    def wake(self, what: bytes = MESSAGE, fenced: bool = False) -> list[int]:
        """One byte (``MESSAGE`` or ``ANNOUNCE``) to every FIFO whose reader is not spinning
        (announcements go to all); returns tokens whose reader is gone. ``fenced``: the caller
        has just run a full fence after publishing, so this one is not needed."""
        dead = []
        states = self._states
        if what == MESSAGE and states and not fenced:
            full_fence()  # our message must be visible before we read who is spinning (module doc)
        for token, fd in self.fds.items():
            if what == MESSAGE:
                state = states.get(token)
                if state is not None and state[1][0] == SPINNING:
                    continue
            try:
                os.write(fd, what)
            except BlockingIOError:
                pass  # FIFO full: the reader has wake-ups pending already
            except BrokenPipeError:
                dead.append(token)
        for token in dead:
            self._forget(token)
        return dead

    def close(self) -> None:
        for token in list(self.fds):
            self._forget(token)
