"""Component health across hosts: every ``<name>/status`` of a run, repeated over Zenoh.

A component publishes its status (health and lifecycle state, the supervisor's heartbeat) on a
shared-memory ring of its run only. The run's Zenoh helper (:mod:`emos.transport.zenoh_status`,
one process per run started with ``--zenoh``) reads those rings and publishes each on
``emos/<group>/<name>/status`` as a ``ComponentStatus``, so a Monitor of another run (another
host) can evaluate events on it (see :mod:`emos.supervisor.monitor_net`).

What crosses, and why:

* a change (status level, lifecycle state, message, failed parts, pid) within
  :data:`COALESCE_S`; an unchanged status at most every :data:`KEEPALIVE_S`: heartbeats are
  10 Hz per component by default, and a remote reader needs to know the component is alive,
  not every beat.
* the publisher keeps the last status for subscribers that join later (TRANSIENT_LOCAL over
  Zenoh): a Monitor that starts after a remote component failed still sees the failure, and
  one that starts after the remote run is gone sees nothing (the cache died with the helper).
* only the component's own ring counts (publisher id = component name), as for the
  supervisor's fallbacks: a stray publisher on ``<name>/status`` is not repeated.
"""
from __future__ import annotations

import logging
import select
import time
from collections.abc import Iterable
from typing import Any

from emos.msgs import codec
from emos.msgs.status import ComponentStatus
from emos.ratelimit import RateLimitedLog
from emos.transport.context import RunContext
from emos.transport.pubsub import Subscriber
from emos.transport.waker import Waker

log = logging.getLogger("emos.transport.zenoh")
KEEPALIVE_S = 0.5
# Wake-ups closer than this are handled together: each component beats at 10 Hz by default, and
# waking once per beat of every component would cost the helper far more than the forwarding.
COALESCE_S = 0.05


def status_topic(component: str) -> str:
    return f"/{component.strip('/')}/status"


def _signature(status: ComponentStatus) -> tuple[object, ...]:
    """What makes a status different from the previous one (not its stamp)."""
    return (status.status, status.lifecycle_state, status.message, tuple(status.src_algorithms),
            tuple(status.src_components), tuple(status.src_topics), status.pid)


class StatusMirror:
    """Reads the status rings of a run's components and publishes them over Zenoh."""

    def __init__(self, ctx: RunContext, config_path: str | None = None, group: str | None = None, keepalive_s: float = KEEPALIVE_S):
        self.ctx = ctx
        self.config_path, self.group = config_path, group
        self.keepalive_s = keepalive_s
        self.waker = Waker(ctx)
        self._subs: dict[str, Subscriber] = {}
        self._pubs: dict[str, Any] = {}
        self._last: dict[str, tuple[tuple[object, ...], float]] = {}  # name -> (signature, monotonic time sent)
        self._errors = RateLimitedLog(log, interval=5.0)
        self.forwarded = 0
        self._last_wake = 0.0

    def watch(self, components: Iterable[str]) -> None:
        """Mirror these components too (ones already mirrored are kept: a component that is
        restarting is still the run's)."""
        from emos.transport.zenoh_net import ZenohPublisher

        for name in components:
            if name in self._subs:
                continue
            topic = status_topic(name)
            try:
                pub = ZenohPublisher(topic, ComponentStatus, publisher_id=name, config_path=self.config_path, group=self.group,
                                     transient_local=True, depth=1)
            except Exception as exc:  # noqa: BLE001 - a name that cannot be a key expression, a session error:
                self._report(name, "cannot be mirrored", exc)  # the others and `emos status --remote` go on
                continue
            self._pubs[name] = pub
            self._subs[name] = Subscriber(self.ctx, topic, ComponentStatus, waker=self.waker, queue_size=16)  # a status ring holds 16

    def wait_and_forward(self, timeout: float) -> int:
        """Wait up to ``timeout`` s for a status, then forward what is due; returns how many."""
        gap = self._last_wake + COALESCE_S - time.monotonic()
        if gap > 0:
            time.sleep(gap)
        ready, _, _ = select.select([self.waker.fd], [], [], timeout)
        self._last_wake = time.monotonic()
        if ready:
            self.waker.drain()
        return self.forward()

    def forward(self) -> int:
        sent = 0
        now = time.monotonic()
        for name, sub in self._subs.items():
            items = [item for item in sub.take_raw() if item[2] == name]
            for k, (_, payload, _) in enumerate(items):
                # Every change crosses, even one undone before we woke (a failure reported for
                # one beat); an unchanged status only when the keepalive is due.
                try:
                    status = codec.decode(ComponentStatus, payload, copy=True)
                except Exception as exc:  # noqa: BLE001 - a corrupt status must not stop the others
                    self._report(name, "status does not decode", exc)
                    continue
                signature = _signature(status)
                last = self._last.get(name)
                if last is not None and last[0] == signature and (k < len(items) - 1 or now - last[1] < self.keepalive_s):
                    continue
                try:
                    self._pubs[name].publish(status)
                except Exception as exc:  # noqa: BLE001 - e.g. the session is closing; try again next time
                    self._report(name, "publishing over Zenoh failed", exc)
                    continue
                self._last[name] = (signature, now)
                sent += 1
        self.forwarded += sent
        return sent

    def _report(self, name: str, what: str, exc: BaseException) -> None:
        self._errors.warning((name, what), "status of %s over Zenoh: %s: %s: %s", name, what, type(exc).__name__, exc)

    def close(self) -> None:
        for sub in self._subs.values():
            sub.close()
        for pub in self._pubs.values():
            pub.close()
        self._subs.clear()
        self._pubs.clear()
        self.waker.close()
