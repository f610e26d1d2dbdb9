"""Wake-ups across processes through named FIFOs an event loop can wait on.

Each subscribing node owns one FIFO in the run directory, named by a random token. Publishers
write one byte to the FIFO of every registered token after each message; the node's event loop
watches the FIFO's file descriptor (``loop.add_reader``), drains it, and polls its rings.
A publisher that appears or goes away writes ``ANNOUNCE`` instead of ``MESSAGE``: subscribers
then look for new rings, which otherwise they need not do on every wake-up.
A FIFO is a plain file descriptor (unlike a futex), works between unrelated processes (unlike an
eventfd, which must be inherited), and lives in the run's mode-0700 directory.
"""
from __future__ import annotations

import errno
import os
import secrets
from pathlib import Path

from emos.transport.context import RunContext

MESSAGE = b"\x01"
ANNOUNCE = b"\x02"


class Waker:
    """The receiving end: a FIFO this node reads."""

    def __init__(self, ctx: RunContext):
        self.token = secrets.randbits(63) | 1
        self.path = fifo_path(ctx, self.token)
        os.mkfifo(self.path, 0o600)
        # O_RDWR keeps the FIFO open for writing too, so it never reports EOF while idle.
        self.fd = os.open(self.path, os.O_RDWR | os.O_NONBLOCK)
        self.announcements = 0  # how many drains saw a publisher appear or go

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

    def close(self) -> None:
        if self.fd >= 0:
            os.close(self.fd)
            self.fd = -1
            try:
                os.unlink(self.path)
            except FileNotFoundError:
                pass


def fifo_path(ctx: RunContext, token: int) -> Path:
    return ctx.run_dir / "wake" / f"{token:016x}"


class WakeSender:
    """The sending end: open FIFOs of the tokens a publisher must wake."""

    def __init__(self, ctx: RunContext):
        self.ctx = ctx
        self.fds: dict[int, int] = {}

    def sync(self, tokens: list[int]) -> list[int]:
        """Open FIFOs for new tokens, close those gone; returns tokens whose reader is dead."""
        dead = []
        wanted = set(tokens)
        for token in list(self.fds):
            if token not in wanted:
                os.close(self.fds.pop(token))
        for token in wanted - set(self.fds):
            try:
                self.fds[token] = os.open(fifo_path(self.ctx, token), os.O_WRONLY | os.O_NONBLOCK)
            except OSError as exc:
                # ENXIO: no reader has it open; ENOENT: the FIFO is gone. Either way its node died.
                if exc.errno in (errno.ENXIO, errno.ENOENT):
                    dead.append(token)
                else:
                    raise
        return dead

    def wake(self, what: bytes = MESSAGE) -> list[int]:
        """One byte (``MESSAGE`` or ``ANNOUNCE``) to every FIFO; returns tokens whose reader is gone."""
        dead = []
        for token, fd in self.fds.items():
            try:
                os.write(fd, what)
            except BlockingIOError:
                pass  # FIFO full: the reader has wake-ups pending already
            except BrokenPipeError:
                dead.append(token)
        for token in dead:
            os.close(self.fds.pop(token))
        return dead

    def close(self) -> None:
        for fd in self.fds.values():
            os.close(fd)
        self.fds.clear()
