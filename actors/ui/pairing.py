"""Pairing a device with a short code, and the brake on guessing codes and tokens.

The run prints a code (``K7QM-2XHD``: 8 characters of a 32-letter alphabet without look-alikes,
40 bits) and a QR code of the pairing page's address with the code in it. A device that sends
the code to ``POST /api/pair`` gets a device token (see :mod:`emos.actors.ui.devices`). A code
is single-use and short-lived: once a device has paired, or ``UIConfig.pairing_code_ttl_s`` (5
minutes) after it was shown, a new one is made, written to ``<run dir>/ui.pairing`` with its
expiry (mode 0600; ``emos ui pair`` shows it with its QR code) and logged. An expired code is
refused with a message saying when it expired.

Guessing is bounded twice: :class:`AttemptLimiter` refuses a client (429) after
``per_client`` failed attempts (wrong codes or wrong tokens) in a minute, and everyone after
``10 * per_client`` failures in a minute from all clients together; each refusal is logged
through one :class:`~emos.ratelimit.RateLimitedLog`, so 1,000 wrong codes make a few lines.
"""
from __future__ import annotations

import collections
import hashlib
import hmac
import json
import secrets
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

ALPHABET = "23456789ABCDEFGHJKLMNPQRSTUVWXYZ"  # no 0/O, 1/I: read off a screen and typed on a tablet
CODE_LEN = 8
PAIRING_NAME = "ui.pairing"


def new_code() -> str:
    raw = "".join(secrets.choice(ALPHABET) for _ in range(CODE_LEN))
    return f"{raw[:4]}-{raw[4:]}"


def normalize(code: Any) -> str:
    """What the user typed, as stored: upper case, without spaces and dashes."""
    if not isinstance(code, str):
        return ""
    return "".join(ch for ch in code.upper() if ch not in " -")


def same_code(given: Any, code: str) -> bool:
    return bool(code) and hmac.compare_digest(normalize(given).encode(), normalize(code).encode())


def code_digest(code: str) -> str:
    """What a device record keeps of the code it paired with (so a restarted UI does not bring a
    used code back): a short hash, never the code."""
    return hashlib.sha256(b"emos-ui-pairing:" + normalize(code).encode()).hexdigest()[:24]


def until_text(expires: float) -> str:
    """An expiry for people: local time of day, with the date when it is not today."""
    when = time.localtime(expires)
    today = time.localtime()
    fmt = "%H:%M:%S" if when[:3] == today[:3] else "%Y-%m-%d %H:%M:%S"
    return time.strftime(fmt, when)


def lifetime_text(seconds: float) -> str:
    return f"{seconds / 60:g} min" if seconds >= 60 else f"{seconds:g} s"


def pairing_url(base: str, code: str) -> str:
    """The address the QR code carries: the pairing page with the code filled in."""
    return f"{base.rstrip('/')}/pair#code={code}"  # in the fragment: never sent to a server, kept out of access logs


def terminal_qr(text: str) -> str:
    """``text`` as a QR code drawn with block characters (segno, from the ui extra), or ``""``."""
    try:
        import io

        import segno
    except ImportError:
        return ""
    out = io.StringIO()
    segno.make(text, error="m").terminal(out=out, compact=True)
    return out.getvalue()


def write_pairing_file(path: Path, code: str, url: str, role: str, expires: float) -> None:
    """The current code for ``emos ui pair``; ``expires``: when it stops working (UNIX time)."""
    from emos.actors.ui.tokenfile import write_private_file

    write_private_file(path, json.dumps({"code": code, "url": url, "role": role, "expires": expires}) + "\n", "the UI's pairing code")


class AttemptLimiter:
    """Failed sign-in attempts per client in a sliding window of ``window`` seconds."""

    def __init__(self, per_client: int, window: float = 60.0, clock: Callable[[], float] = time.monotonic, max_clients: int = 4096):
        self.per_client, self.window, self.clock = per_client, window, clock
        self.overall = 10 * per_client
        self.max_clients = max_clients
        self._failures: collections.OrderedDict[str, collections.deque[float]] = collections.OrderedDict()
        self._all: collections.deque[float] = collections.deque()

    def _trim(self, q: collections.deque[float], now: float) -> None:
        while q and q[0] <= now - self.window:
            q.popleft()

    def blocked(self, client: str) -> float:
        """Seconds until ``client`` may try again (0: it may try now)."""
        now = self.clock()
        self._trim(self._all, now)
        q = self._failures.get(client)
        if q is not None:
            self._trim(q, now)
        waits = []
        if q is not None and len(q) >= self.per_client:
            waits.append(q[0] + self.window - now)
        if len(self._all) >= self.overall:
            waits.append(self._all[0] + self.window - now)
        return max(waits, default=0.0)

    def failed(self, client: str) -> None:
        now = self.clock()
        q = self._failures.pop(client, None) or collections.deque(maxlen=self.per_client)
        q.append(now)
        self._failures[client] = q  # most recent last; the oldest client is forgotten first
        if len(self._failures) > self.max_clients:
            self._failures.popitem(last=False)
        self._all.append(now)
        if len(self._all) > self.overall:
            self._all.popleft()
