"""emos.core.retry: attempts, the delays asked for (exponential, capped, cut at the deadline),
which exceptions are retried, and the sync and async runners alike. A fake clock that the
injected sleep advances: nothing here waits."""
import asyncio

import pytest

from emos.core.retry import Backoff, retry, retry_async

pytestmark = pytest.mark.unit


class FakeTime:
    def __init__(self):
        self.now = 100.0
        self.slept: list[float] = []

    def clock(self):
        return self.now

    def sleep(self, s):
        self.slept.append(s)
        self.now += s

    async def asleep(self, s):
        self.sleep(s)


class Flaky:
    """Raises ``exc`` the first ``fails`` calls, then returns the call count; may take time."""

    def __init__(self, fails, exc=ConnectionError, took=0.0, t=None):
        self.fails, self.exc, self.took, self.t, self.calls = fails, exc, took, t, 0

    def __call__(self):
        self.calls += 1
        if self.t is not None:
            self.t.now += self.took
        if self.calls <= self.fails:
            raise self.exc(f"failure {self.calls}")
        return self.calls


def run(call, policy, t, **kw):
    return retry(call, policy, sleep=t.sleep, clock=t.clock, **kw)


def test_exponential_delays_until_success():
    t = FakeTime()
    flaky = Flaky(3)
    assert run(flaky, Backoff(attempts=5, base=0.5, factor=2.0), t) == 4
    assert flaky.calls == 4 and t.slept == [0.5, 1.0, 2.0]


def test_attempts_bound_the_calls_and_the_last_exception_is_raised_unchanged():
    t = FakeTime()
    flaky = Flaky(10)
    with pytest.raises(ConnectionError, match="failure 3"):
        run(flaky, Backoff(attempts=3, base=0.1), t)
    assert flaky.calls == 3 and t.slept == pytest.approx([0.1, 0.2])
    one = Flaky(10)
    with pytest.raises(ConnectionError, match="failure 1"):
        run(one, Backoff(attempts=1), t)
    assert one.calls == 1 and t.slept == pytest.approx([0.1, 0.2])  # no wait added


def test_the_cap_bounds_each_delay_and_a_factor_of_one_is_a_constant_delay():
    t = FakeTime()
    run(Flaky(6), Backoff(attempts=10, base=0.01, factor=2.0, cap=0.05), t)
    assert t.slept == pytest.approx([0.01, 0.02, 0.04, 0.05, 0.05, 0.05])
    t2 = FakeTime()
    run(Flaky(3), Backoff(attempts=4, base=0.3, factor=1.0), t2)
    assert t2.slept == pytest.approx([0.3, 0.3, 0.3])


def test_a_timeout_retries_until_the_deadline_cutting_the_last_wait_then_gives_up():
    t = FakeTime()
    flaky = Flaky(100)
    with pytest.raises(ConnectionError):
        run(flaky, Backoff(base=0.01, factor=2.0, cap=0.2, timeout=1.0), t)
    # 0.01 + 0.02 + 0.04 + 0.08 + 0.16 + 0.2 + 0.2 = 0.71, then 0.2, then the 0.09 left.
    assert t.slept == pytest.approx([0.01, 0.02, 0.04, 0.08, 0.16, 0.2, 0.2, 0.2, 0.09])
    assert sum(t.slept) == pytest.approx(1.0) and flaky.calls == len(t.slept) + 1  # one last call at the deadline


def test_time_spent_in_the_calls_counts_against_the_timeout():
    t = FakeTime()
    flaky = Flaky(100, took=0.4, t=t)
    with pytest.raises(ConnectionError):
        run(flaky, Backoff(base=0.1, factor=1.0, timeout=1.0), t)
    # call (0.4) wait 0.1, call (0.9) wait 0.1, call (1.4): past the deadline
    assert flaky.calls == 3 and t.slept == pytest.approx([0.1, 0.1])


def test_a_zero_timeout_is_one_call():
    t = FakeTime()
    flaky = Flaky(5)
    with pytest.raises(ConnectionError):
        run(flaky, Backoff(timeout=0.0), t)
    assert flaky.calls == 1 and t.slept == []


def test_only_the_named_exceptions_and_those_retry_if_accepts_are_retried():
    t = FakeTime()
    other = Flaky(5, exc=KeyError)
    with pytest.raises(KeyError):
        run(other, Backoff(attempts=5), t, retry_on=ConnectionError)
    assert other.calls == 1

    class Status(Exception):
        def __init__(self, msg):
            super().__init__(msg)
            self.code = 503 if "1" in msg else 404

    statuses = Flaky(5, exc=Status)
    with pytest.raises(Status, match="failure 2"):  # 503 retried, 404 not
        run(statuses, Backoff(attempts=5), t, retry_on=Status, retry_if=lambda e: e.code == 503)
    assert statuses.calls == 2 and t.slept == [0.1]


def test_on_retry_hears_each_failure_with_its_number_and_delay():
    t = FakeTime()
    heard = []
    run(Flaky(2), Backoff(attempts=3, base=0.25), t, on_retry=lambda exc, n, d: heard.append((str(exc), n, d)))
    assert heard == [("failure 1", 1, 0.25), ("failure 2", 2, 0.5)]


def test_the_async_runner_behaves_the_same():
    t = FakeTime()
    flaky = Flaky(3)

    async def call():
        return flaky()

    result = asyncio.run(retry_async(call, Backoff(attempts=5, base=0.5, cap=1.5), sleep=t.asleep, clock=t.clock))
    assert result == 4 and t.slept == [0.5, 1.0, 1.5]
    t2 = FakeTime()
    never = Flaky(100)

    async def call2():
        return never()

    with pytest.raises(ConnectionError):
        asyncio.run(retry_async(call2, Backoff(base=0.2, factor=1.0, timeout=0.5), sleep=t2.asleep, clock=t2.clock))
    assert t2.slept == pytest.approx([0.2, 0.2, 0.1])


def test_a_cancelled_async_call_is_not_retried():
    t = FakeTime()
    calls = []

    async def call():
        calls.append(1)
        raise asyncio.CancelledError

    with pytest.raises(asyncio.CancelledError):
        asyncio.run(retry_async(call, Backoff(attempts=5), sleep=t.asleep, clock=t.clock))
    assert calls == [1] and t.slept == []


@pytest.mark.parametrize("kwargs, match", [
    ({}, "give attempts or timeout"),
    ({"attempts": 0}, "attempts must be an integer >= 1"),
    ({"attempts": True}, "attempts must be an integer >= 1"),
    ({"attempts": 2, "base": -1}, "base must be a number >= 0"),
    ({"attempts": 2, "cap": float("nan")}, "cap must be a number >= 0"),
    ({"timeout": -0.5}, "timeout must be a number >= 0"),
])
def test_a_bad_policy_is_refused_when_defined(kwargs, match):
    with pytest.raises(ValueError, match=match):
        Backoff(**kwargs)


def test_the_model_client_retries_transient_failures_with_its_backoff(monkeypatch):
    """actors.agents' ModelClient keeps its max_retries / retry_backoff meaning: max_retries + 1
    calls, retry_backoff doubling, and a non-transient status is not retried."""
    import emos.core.retry as R
    from emos.actors.agents.clients.base import ModelClient
    from emos.actors.agents.errors import ModelConnectionError, ModelServerError
    from emos.actors.agents.models import GenericLLM

    slept = []
    monkeypatch.setattr(R.time, "sleep", slept.append)

    class Client(ModelClient):
        pass

    client = Client(GenericLLM(name="m", checkpoint="x"), max_retries=3, retry_backoff=0.5)
    flaky = Flaky(10, exc=lambda msg: ModelConnectionError(msg, client="c", model="m", url="u"))
    with pytest.raises(ModelConnectionError):
        client._retrying(flaky)
    assert flaky.calls == 4 and slept == [0.5, 1.0, 2.0]
    slept.clear()
    refused = Flaky(10, exc=lambda msg: ModelServerError(msg, status=404, client="c", model="m", url="u"))
    with pytest.raises(ModelServerError):
        client._retrying(refused)
    assert refused.calls == 1 and slept == []
    with pytest.raises(ValueError, match="retry_backoff"):
        Client(GenericLLM(name="m", checkpoint="x"), retry_backoff=-1)
