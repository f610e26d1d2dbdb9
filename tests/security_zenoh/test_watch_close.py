"""Closing a SecurityWatch never undeclares its subscriber while one of its admin-space queries is
in flight: Zenoh 1.10 can deadlock there (the undeclare and the query's reply wait for each
other's locks; a suite run hung in ``close`` for good, beyond pytest-timeout's reach)."""
from __future__ import annotations

import threading
import time
from typing import Any

import pytest

pytestmark = pytest.mark.process

zenoh = pytest.importorskip("zenoh", reason="the 'net' extra (eclipse-zenoh) is not installed")

from emos.security.watch import SecurityWatch  # noqa: E402


class _CountingSession:
    """A real Zenoh session whose ``get`` counts the queries in flight and, while ``hold`` is
    clear, waits before asking (so a test can close the watch with a query in flight)."""

    def __init__(self, session: Any):
        self._session = session
        self.in_flight = 0
        self.started = threading.Event()
        self.hold = threading.Event()
        self._lock = threading.Lock()

    def __getattr__(self, name: str) -> Any:
        return getattr(self._session, name)

    def get(self, selector: str, **kwargs: Any) -> list[Any]:
        with self._lock:
            self.in_flight += 1
        try:
            self.started.set()
            self.hold.wait(timeout=10.0)
            return list(self._session.get(selector, **kwargs))
        finally:
            with self._lock:
                self.in_flight -= 1


class _CheckedSubscriber:
    """The watch's real subscriber; records how many queries were in flight at its undeclare."""

    def __init__(self, sub: Any, session: _CountingSession):
        self._sub, self._session = sub, session
        self.in_flight_at_undeclare: int | None = None

    def undeclare(self) -> None:
        self.in_flight_at_undeclare = self._session.in_flight
        self._sub.undeclare()


def test_close_waits_for_the_check_in_flight_before_undeclaring():
    config = zenoh.Config()
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("listen/endpoints", "[]")
    real = zenoh.open(config)
    try:
        session = _CountingSession(real)
        watch = SecurityWatch(session, {"rules": [], "subjects": [], "policies": []}, "watch-close-test")
        checked = _CheckedSubscriber(watch._sub, session)
        watch._sub = checked
        # A publisher announcement, as an EMOS publisher declares it: the watch checks it with
        # admin-space queries, the first of which the session holds.
        token = real.liveliness().declare_token("emos/watch-close-test/cmd_vel/_pub_/Twist/alice")
        assert session.started.wait(timeout=10.0), "the watch never checked the announcement"
        closer = threading.Thread(target=watch.close)
        closer.start()
        time.sleep(0.3)  # close() is waiting for the check; nothing undeclared yet
        assert checked.in_flight_at_undeclare is None
        session.hold.set()
        closer.join(timeout=30.0)
        assert not closer.is_alive(), "close() did not return"
        assert checked.in_flight_at_undeclare == 0
        token.undeclare()
    finally:
        real.close()
