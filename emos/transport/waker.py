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
``spin_us=0`` turns it off. A linger lasts at most ``MAX_LINGER_US`` (so the event loop still
runs timers and RPCs under a flood); if messages were still flowing when it ended, the node does
not park: it pokes its own FIFO and keeps the flag, so publishers still skip the FIFO and the
event loop calls it again after its other work (a park there made the next message pay a full
wake-up: at 8 MiB, whose round trip outlasts the linger, most messages).

Long writes. A fixed spin window fails for big messages: copying a 921,600 B frame takes about
as long as the window, an 8 MiB one ten times longer, so the reader parked in the middle of the
copy and paid the whole FIFO and event-loop wake-up after it (hundreds of microseconds on a
loaded VM, the p50 of issue 34). So a publisher about to copy a big message (a) writes into its
ring's header when it expects the copy to be done (``Ring.announce``), and (b) wakes, at once,
the parked readers that linger (the ``_EARLY`` word of their state page): their wake-up now runs
*during* the copy instead of after it. A lingering reader that sees a write in progress keeps
spinning until the announced deadline (bounded by ``MAX_BUSY_US``); past its linger deadline it
pokes itself and returns, so the event loop still gets its turn. Correctness never rests on the
announcement: the publisher still consults the state word after the commit and writes the FIFO
to a reader that has parked, and a writer killed mid-copy leaves a deadline that simply passes.

Robot first. A publisher wakes its subscribers one system call after the other, and on a
machine with few cores the first woken takes the free core. Best-effort readers (the Monitor
evaluating events, the web UI, a recorder) mark their token with :data:`BACKGROUND_BIT`, and
publishers wake them after every other subscriber, so the robot's own components are not queued
behind them. The bit only orders wake-ups: a peer that sets it on its own token harms no one but
itself.

Leftovers of a killed reader. A reader's FIFO and state page (and its entry in the topics'
subscriber lists) are removed by its ``close``; a reader killed outright (SIGKILL) cannot. So the
state page names its owner (pid and process start time, which a reused pid does not share), and
a reader counts as dead when no process holds its FIFO open for reading *and* its owner is gone.
Publishers remove a dead reader's files as soon as a wake-up fails (:class:`WakeSender`), and
:func:`sweep_dead_wakers` removes those of readers nobody publishes to.
"""
from __future__ import annotations

import errno
import mmap
import os
import secrets
import stat
import struct
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from emos.transport.context import RunContext, make_run_id, run_is_alive
from emos.transport.fence import full_fence
from emos.transport.trust import distrust_reason, rate_limited

MESSAGE = b"\x01"
ANNOUNCE = b"\x02"
PARKED, SPINNING = 0, 1  # the state word a Waker shares with the publishers that wake it
DEFAULT_SPIN_US = 100.0  # longer than a request-reply turnaround here; at most this CPU per message
MAX_LINGER_US = 1000.0  # under a flood, return to the event loop this often (timers, RPC, signals)
_STATE_BYTES = 64
BACKGROUND_BIT = 1 << 62  # in a token: wake this reader after the others (module doc)
_OWNER_PID, _OWNER_START = 1, 2  # words of the state page naming the reader's process (module doc)
_EARLY = 3  # state word: 1 if this reader lingers and wants a wake-up when a long write starts
MAX_BUSY_US = 50_000.0  # a write announced to end farther ahead than this is not waited for
_MAX_BUSY_NS = int(MAX_BUSY_US * 1000)


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
        self._watched: list[Any] = []  # subscribers whose rings may announce long writes (watch)
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
            self._state[_OWNER_START] = _own_start_token()
            self._state[_OWNER_PID] = os.getpid()
            # Background readers are never woken early: they come after the robot's own readers.
            self._state[_EARLY] = int(self.spin_ns > 0 and not background)
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

    def watch(self, source: Any) -> None:
        """Let :meth:`serve` keep spinning while ``source.busy_until()`` (a monotonic ns
        deadline, 0 for none) says one of its publishers is in the middle of a long write."""
        if source not in self._watched:
            self._watched.append(source)

    def unwatch(self, source: Any) -> None:
        if source in self._watched:
            self._watched.remove(source)

    def _busy_until(self, now: int) -> int:
        """The latest plausible write deadline announced on the rings we read, or 0."""
        best = 0
        for source in self._watched:
            until = source.busy_until()
            if now < until <= now + _MAX_BUSY_NS and until > best:
                best = until
        return best

    def serve(self, handle: Callable[[], None], has_news: Callable[[], bool]) -> None:
        """Handle one wake-up: drain, ``handle()``, then linger for more (see module doc).

        ``has_news`` must be cheap (it runs in the spin loop): it says whether any ring this
        node reads has a message ``handle`` has not taken yet.
        """
        self.drain()
        handle()
        if self.spin_ns <= 0:
            return
        clock = time.monotonic_ns  # the clock publishers announce write deadlines on
        yield_cpu = os.sched_yield
        state = self._state
        state[0] = SPINNING
        # Our linger deadline came while messages still flowed (or a long write was announced):
        # give the event loop its turn and come straight back, still spinning (module doc).
        keep = False
        try:
            # Under a flood, give the event loop its turn now and then (timers, RPC, signals).
            deadline = clock() + max(int(MAX_LINGER_US * 1000), 2 * self.spin_ns)
            while True:
                idle_end = clock() + self.spin_ns
                while not has_news():
                    now = clock()
                    if now >= idle_end:
                        # A publisher announced a long write: wait for it rather than park in
                        # the middle of its copy (module doc); the deadline below still holds.
                        until = self._busy_until(now) if self._watched else 0
                        if not until:
                            return  # idle: park
                        idle_end = until
                    if now >= deadline:
                        keep = True  # a message within the last spin window, or a write under way
                        return
                    # Give the CPU to whoever else can run on it (likely the very publisher we
                    # wait for, when both share a CPU); returns at once when nobody can.
                    yield_cpu()
                handle()
                if clock() >= deadline:
                    keep = True
                    return
        finally:
            if keep:
                # Still SPINNING in the publishers' eyes, so they write no wake-up: the poke
                # makes the event loop call serve() again after its other work, and that call
                # takes whatever they published meanwhile. Parking here instead cost a full
                # wake-up (FIFO, scheduler, event loop) on the next message, every
                # MAX_LINGER_US: at 8 MiB, where a round trip outlasts it, on most messages.
                self.poke()
            else:
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
                    remove_if_dead(self.ctx, token)
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
            remove_if_dead(self.ctx, token)
        return dead

    def wake_early(self) -> None:
        """Wake the parked readers that linger (module doc: long writes) as a long copy starts,
        so their wake-up overlaps it. Only a head start: :meth:`wake` after the commit still
        wakes whoever parked by then, so nothing here needs a fence, and errors wait for it."""
        states = self._states
        for token, fd in self.fds.items():
            state = states.get(token)
            if state is None or state[1][_EARLY] != 1 or state[1][0] == SPINNING:
                continue
            try:
                os.write(fd, MESSAGE)
            except OSError:
                pass  # full (a wake-up is pending) or gone (wake() reports it)

    def close(self) -> None:
        for token in list(self.fds):
            self._forget(token)


# ---------------------------------------------------------------------------- leftovers of dead readers
_start_tokens: dict[int, int] = {}  # pid -> start token; keyed by pid because a fork has its own


def _own_start_token() -> int:
    """This process's start time as run ids spell it (0 if unreadable: never judged dead)."""
    pid = os.getpid()
    token = _start_tokens.get(pid)
    if token is None:
        try:
            token = int(make_run_id(pid).split("-")[1])
        except (RuntimeError, ValueError, IndexError):
            token = 0
        _start_tokens.clear()
        _start_tokens[pid] = token
    return token


def _lstat(path: Path) -> os.stat_result | None:
    try:
        return os.lstat(path)
    except FileNotFoundError:
        return None


def _fifo_has_reader(path: Path) -> bool:
    """Whether some process holds the FIFO open for reading (our Waker holds it O_RDWR)."""
    try:
        fd = os.open(path, os.O_WRONLY | os.O_NONBLOCK | os.O_NOFOLLOW | os.O_CLOEXEC)
    except OSError as exc:
        # ENXIO: nobody reads it; ENOENT: gone. Anything else (not a FIFO of ours, a link): we
        # cannot tell, so it counts as read and is left alone.
        return exc.errno not in (errno.ENXIO, errno.ENOENT)
    os.close(fd)
    return True


def _owner_alive(path: Path) -> bool | None:
    """Whether the process named in a state page still runs; None if the page names none yet
    (being made) or cannot be read as ours."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_CLOEXEC | os.O_NONBLOCK)
    except OSError:
        return None
    try:
        if distrust_reason(os.fstat(fd), 0o600) is not None:
            return None
        data = os.pread(fd, 8 * (_OWNER_START + 1), 0)
    except OSError:
        return None
    finally:
        os.close(fd)
    if len(data) < 8 * (_OWNER_START + 1):
        return None
    pid, start = struct.unpack_from("=QQ", data, 8 * _OWNER_PID)
    if pid == 0 or start == 0 or pid > 2**31:
        return None
    return run_is_alive(f"{pid}-{start}")


def _unlink_ours(path: Path, fifo: bool) -> None:
    st = _lstat(path)
    if st is None:
        return
    ours = st.st_uid == os.geteuid() and (stat.S_ISFIFO(st.st_mode) if fifo else distrust_reason(st, 0o600) is None)
    if not ours:
        rate_limited.warning(f"wake:{path}", "wake-ups: leaving %s in place: it is not a %s of ours", path, "FIFO" if fifo else "state page")
        return
    try:
        os.unlink(path)
    except FileNotFoundError:
        pass
    except OSError as exc:
        rate_limited.warning(f"wake:{path}", "wake-ups: cannot remove %s: %s", path, exc.strerror)


def remove_if_dead(ctx: RunContext, token: int) -> bool:
    """Remove the FIFO and state page of reader ``token`` if it is dead (module doc); returns
    whether it was judged dead (also when its files were already gone)."""
    fifo, state = fifo_path(ctx, token), state_path(ctx, token)
    fifo_st, state_st = _lstat(fifo), _lstat(state)
    if fifo_st is not None and _fifo_has_reader(fifo):
        return False
    # The state page is made first and removed last, so without it nothing is half made; with it,
    # a live owner may be closing or still opening its FIFO, and an unreadable page is not ours to judge.
    if state_st is not None and _owner_alive(state) is not False:
        return False
    _unlink_ours(fifo, fifo=True)
    _unlink_ours(state, fifo=False)
    return True


def _token_of(name: str) -> int | None:
    stem = name.removesuffix(".state")
    if len(stem) != 16:
        return None
    try:
        return int(stem, 16)
    except ValueError:
        return None


def sweep_dead_wakers(ctx: RunContext) -> int:
    """Remove the wake-up files of readers killed without closing (module doc) and their
    entries in the subscriber lists of the run; returns how many readers were swept.
    Never raises for what it finds: a run directory holds only our files, but is read as untrusted."""
    wake_dir = ctx.run_dir / "wake"
    try:
        names = os.listdir(wake_dir)
    except OSError:
        return 0
    live: set[int] = set()
    swept = 0
    for token in {t for t in map(_token_of, names) if t is not None}:
        if remove_if_dead(ctx, token):
            swept += 1
        else:
            live.add(token)
    try:
        topics = list((ctx.run_dir / "subs").iterdir())
    except OSError:
        return swept
    for folder in topics:
        try:
            entries = list(folder.iterdir())
        except OSError:
            continue
        for entry in entries:
            reader = _token_of(entry.name)
            # A subscriber registers after its waker is made: an entry whose waker has no file
            # left belongs to a reader that is gone (or is closing, and removes it anyway).
            if reader is None or reader in live or _lstat(fifo_path(ctx, reader)) or _lstat(state_path(ctx, reader)):
                continue
            st = _lstat(entry)
            if st is not None and stat.S_ISREG(st.st_mode) and st.st_uid == os.geteuid():
                try:
                    entry.unlink()
                except FileNotFoundError:
                    pass
    return swept
