"""An event may fire while the component that serves its action or service is still starting (a
detector up before the controller it switches): the Monitor's goal and request wait for the
server, up to the action timeout, and are sent once. Real Unix sockets, a real ActionServer and
ServiceServer on an event loop of their own, started after the client has already failed."""
import asyncio
import logging
import threading
import time

import pytest

from emos import msgs as M
from emos.core.rpc import RpcConnectionError, RpcUnreachable
from emos.core.services import ActionClient, ActionServer, ServiceServer, call_service_async
from emos.events.runner import ActionRuntime
from emos.msgs.srv import FibonacciFeedback, FibonacciGoal, FibonacciResult
from emos.transport.context import RunContext
from tests.runtime.helpers import wait_until

pytestmark = pytest.mark.process


class _Runtime(ActionRuntime):
    """The Monitor's way of sending goals and calling services, without the Monitor."""

    def __init__(self, ctx: RunContext):
        self.ctx, self.log, self.timeout = ctx, logging.getLogger("test.wait_for_server"), 60.0


class _ServerLoop:
    """An event loop in a thread, to start servers on later."""

    def __init__(self) -> None:
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self.thread.start()
        self.servers: list = []

    def start(self, server) -> None:
        asyncio.run_coroutine_threadsafe(server.start(), self.loop).result(10)
        self.servers.append(server)

    def close(self) -> None:
        for server in self.servers:
            asyncio.run_coroutine_threadsafe(server.close(), self.loop).result(10)
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(10)


@pytest.fixture
def run():
    ctx = RunContext.create()
    servers = _ServerLoop()
    yield ctx, servers
    servers.close()
    ctx.remove_everything()


def _fibonacci(goals: list):
    def execute(handle):
        goals.append(handle.goal.order)
        return FibonacciResult(sequence=[0, 1, 1][: handle.goal.order])
    return execute


def test_an_events_goal_waits_for_an_action_server_that_starts_after_it_fired(run):
    ctx, servers = run
    goals: list[int] = []
    client = ActionClient("/late/fibonacci", FibonacciGoal, FibonacciFeedback, FibonacciResult, ctx=ctx)
    with pytest.raises(RpcUnreachable, match="cannot connect"):  # not serving: without waiting, it fails at once
        client.send_goal(FibonacciGoal(order=3))

    # asyncio.run returns once the detached goal's worker thread is done (it shuts the executor down).
    sender = threading.Thread(target=lambda: asyncio.run(_Runtime(ctx).send_goal(
        "/late/fibonacci", (FibonacciGoal, FibonacciFeedback, FibonacciResult), FibonacciGoal(order=3))), daemon=True)
    sender.start()
    time.sleep(0.3)  # the event has fired and its first connection attempts have failed
    assert goals == []
    servers.start(ActionServer(ctx, "/late/fibonacci", FibonacciGoal, FibonacciFeedback, FibonacciResult, _fibonacci(goals)))
    wait_until(lambda: goals, timeout=60, what="the goal at the late action server")
    sender.join(60)
    assert not sender.is_alive() and goals == [3], "the goal is sent once"


def test_an_events_service_call_waits_for_a_server_that_starts_later(run):
    ctx, servers = run
    requests: list[bool] = []

    def serve(request):
        requests.append(request.data)
        return M.SetBoolResponse(success=True, message="done")

    result: dict = {}

    def call() -> None:
        result["response"] = asyncio.run(_Runtime(ctx).call_service("/late/enable", M.SetBoolRequest(data=True), M.SetBoolResponse))

    caller = threading.Thread(target=call, daemon=True)
    caller.start()
    time.sleep(0.3)
    assert requests == [] and "response" not in result
    servers.start(ServiceServer(ctx, "/late/enable", M.SetBoolRequest, M.SetBoolResponse, serve))
    caller.join(60)
    assert result["response"].success and result["response"].message == "done"
    assert requests == [True], "the request is sent once"


def test_a_server_that_never_comes_fails_with_the_socket_named(run):
    ctx, _ = run
    with pytest.raises(RpcUnreachable, match=r"cannot connect to .*nobody~here\.sock"):
        asyncio.run(call_service_async(ctx, "/nobody/here", M.SetBoolRequest(data=True), M.SetBoolResponse, wait_for_service=0.2))
    assert issubclass(RpcUnreachable, RpcConnectionError), "callers that catch RpcConnectionError still catch it"
