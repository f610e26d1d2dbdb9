"""Which of a topic's segments a subscriber opens, and what it remembers about those it refused.

Another user can plant any name in a run's namespace (a forged ring, a directory, a link, a
higher generation number of a real publisher's ring), and a writer of ours can leave a damaged
ring. A subscriber looks at each publisher's newest segment *that passes the owner check*, opens
it only through ``Ring.attach`` (owner, mode, header), and sets aside for a while whatever fails
there or later while being read, saying so once per segment and interval.
"""
from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable

from emos.ratelimit import RateLimitedLog
from emos.transport import ring as R
from emos.transport.context import SHM_DIR
from emos.transport.trust import UntrustedFile, check_path

# A refused segment is looked at again after this long: our own writers never reuse a name for
# other contents, but a damaged ring may be replaced meanwhile (under a new generation).
RETRY_REJECTED_NS = 2_000_000_000
_MAX_VERDICTS = 1024  # names are cheap to mint: the oldest verdicts are forgotten beyond this

log = logging.getLogger("emos.transport")


class SegmentScreen:
    """One subscriber's view of which segments of its topic it may read."""

    def __init__(self, topic: str, prefix: str, parse: Callable[[str], tuple[str, str, int] | None]):
        self.topic = topic
        self.prefix = prefix
        self.parse = parse
        self.warn = RateLimitedLog(log)  # per subscriber: each one says once what it ignores
        self._rejected: dict[str, int] = {}  # segment name -> monotonic ns until which it is ignored

    def candidates(self, held: dict[str, str]) -> dict[str, list[tuple[int, str]]]:
        """``{publisher: [(generation, segment), ...] newest first}``.

        Only regular files of ours that were not refused lately are candidates; ``held``
        (publisher -> segment we read already, trusted when it was opened) always is. Another
        user may plant any generation number: it must not hide the real one.
        """
        found: dict[str, list[tuple[int, str]]] = {}
        for name in os.listdir(SHM_DIR):
            if not name.startswith(self.prefix):
                continue
            parsed = self.parse(name)
            if parsed is not None:
                found.setdefault(parsed[1], []).append((parsed[2], name))
        now = time.monotonic_ns()
        out: dict[str, list[tuple[int, str]]] = {}
        held_names = set(held.values())
        for pub, gens in found.items():
            keep = []
            for gen, name in sorted(gens, reverse=True):
                if name not in held_names:
                    if self._rejected.get(name, 0) > now:
                        continue
                    reason = check_path(SHM_DIR / name)
                    if reason is not None:
                        if reason != "vanished":
                            self.reject(name, reason)
                        continue
                keep.append((gen, name))
            if keep:
                out[pub] = keep
        return out

    def attach(self, name: str, generation: int) -> R.Ring | None:
        """The one way a subscriber opens a ring: validated, or refused with a warning."""
        try:
            return R.Ring.attach(name, generation=generation)
        except (R.RingError, UntrustedFile) as exc:
            self.reject(name, str(exc))
            return None

    def reject(self, name: str, reason: str) -> None:
        self._rejected[name] = time.monotonic_ns() + RETRY_REJECTED_NS
        if len(self._rejected) > _MAX_VERDICTS:
            for old in sorted(self._rejected, key=self._rejected.__getitem__)[: _MAX_VERDICTS // 2]:
                del self._rejected[old]
        self.warn.warning(f"reject:{name}", "topic %s: ignoring segment %s: %s", self.topic, name, reason)
