"""Rate-limited logging, the one home (emos.ratelimit): first occurrence at once, then at most
one line per interval per key with the count of those left out, on a manual clock."""
from __future__ import annotations

import logging

import pytest

from emos.ratelimit import RateLimitedLog

pytestmark = pytest.mark.unit


class ManualClock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t

    def advance(self, dt: float) -> None:
        self.t += dt


class Lines(logging.Handler):
    def __init__(self) -> None:
        super().__init__(logging.DEBUG)
        self.records: list[logging.LogRecord] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append(record)

    @property
    def text(self) -> list[str]:
        return [r.getMessage() for r in self.records]


@pytest.fixture
def logger():
    lg = logging.getLogger("emos.test.ratelimit")
    lines = Lines()
    lg.addHandler(lines)
    lg.setLevel(logging.DEBUG)
    lg.propagate = False
    try:
        yield lg, lines
    finally:
        lg.removeHandler(lines)
        lg.propagate = True


def test_first_occurrence_at_once_then_one_line_per_interval_with_the_count_left_out(logger):
    lg, lines = logger
    clock = ManualClock()
    limited = RateLimitedLog(lg, interval=10.0, clock=clock)
    # 64 Hz (a step exact in binary) for 25 s: 1,600 occurrences, 3 lines (t = 0, 10, 20).
    for _ in range(1600):
        limited.warning("distrust:seg", "topic %s: ignoring segment %s", "/scan", "seg")
        clock.advance(1 / 64)
    assert lines.text[0] == "topic /scan: ignoring segment seg"
    assert lines.text[1:] == ["topic /scan: ignoring segment seg (x639 in the last 10.0 s)"] * 2
    assert [r.levelno for r in lines.records] == [logging.WARNING] * 3
    assert limited.count("distrust:seg") == 1600


def test_keys_are_limited_separately_and_the_return_value_says_whether_it_logged(logger):
    lg, lines = logger
    clock = ManualClock()
    limited = RateLimitedLog(lg, interval=5.0, clock=clock)
    assert limited.error("a", "peer %s refused", "a") is True
    assert limited.error("b", "peer %s refused", "b") is True  # another key: not held back by a
    assert limited.error("a", "peer %s refused", "a") is False
    clock.advance(4.99)
    assert limited.error("a", "peer %s refused", "a") is False
    clock.advance(0.01)
    assert limited.error("a", "peer %s refused", "a") is True
    assert lines.text == ["peer a refused", "peer b refused", "peer a refused (x2 in the last 5.0 s)"]
    assert [r.levelno for r in lines.records] == [logging.ERROR] * 3


def test_a_problem_that_comes_back_after_a_quiet_spell_has_no_count_and_a_clock_that_went_back_logs(logger):
    lg, lines = logger
    clock = ManualClock()
    limited = RateLimitedLog(lg, interval=10.0, clock=clock)
    limited.warning("k", "once")
    clock.advance(60.0)
    limited.warning("k", "once")  # nothing was left out: no count
    clock.t = 0.0  # a restarted simulated clock: a new interval starts, nothing is swallowed for long
    limited.warning("k", "once")
    assert lines.text == ["once", "once", "once"]


def test_per_call_logger_and_messages_with_percent_signs_from_peers(logger):
    lg, lines = logger
    limited = RateLimitedLog(interval=1.0, clock=ManualClock())  # no default logger: one per call
    limited.warning("input:scan", "[%s] %s", "controller", "100% of ranges are NaN", logger=lg)
    assert lines.text == ["[controller] 100% of ranges are NaN"]


def test_exceptions_first_with_the_traceback_then_counted_lines_pointing_back(logger):
    lg, lines = logger
    clock = ManualClock()
    limited = RateLimitedLog(lg, interval=5.0, clock=clock)

    def step():
        raise ValueError("bad reading")

    for _ in range(768):  # 64 Hz for 12 s
        try:
            step()
        except ValueError as exc:
            limited.exception(exc, "[broken] execution step")
        clock.advance(1 / 64)
    assert len(lines.records) == 3
    assert lines.records[0].exc_info is not None and lines.text[0] == "[broken] execution step raised: bad reading"
    assert all(r.exc_info is None for r in lines.records[1:])
    assert lines.text[1] == "[broken] execution step raised ValueError: bad reading again (x319 in the last 5.0 s, 321 in all; traceback above)"
    assert lines.text[2] == "[broken] execution step raised ValueError: bad reading again (x319 in the last 5.0 s, 641 in all; traceback above)"

    # Another error (other message) is a key of its own: its own traceback at once.
    try:
        raise ValueError("other")
    except ValueError as exc:
        assert limited.exception(exc, "[broken] execution step")
    assert lines.records[-1].exc_info is not None


def test_keys_peers_can_mint_are_bounded_forgetting_the_least_recently_logged(logger):
    lg, lines = logger
    clock = ManualClock()
    limited = RateLimitedLog(lg, interval=10.0, clock=clock, max_keys=3)
    for name in ("a", "b", "c"):
        limited.warning(name, "segment %s", name)
    clock.advance(10.0)
    limited.warning("a", "segment %s", "a")  # logged again: now the most recent
    limited.warning("d", "segment %s", "d")  # a fourth key forgets b, the least recently logged
    assert limited.count("b") == 0 and limited.count("a") == 2 and limited.count("c") == 1
    assert len(limited._seen) == 3
    assert lines.text == ["segment a", "segment b", "segment c", "segment a", "segment d"]


def test_bad_settings_are_refused_naming_them():
    with pytest.raises(ValueError, match="interval must be"):
        RateLimitedLog(interval=-1.0)
    with pytest.raises(ValueError, match="max_keys must be"):
        RateLimitedLog(max_keys=0)


def test_the_transports_shared_limiter_is_the_one_home():
    from emos.transport import trust

    assert isinstance(trust.rate_limited, RateLimitedLog)
