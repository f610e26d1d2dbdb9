"""Actions through the ROS 2 bridge, both ways, against real rclpy action servers and clients
(tests/ros2/peers/action.py): test_msgs/action/Fibonacci with feedback, result and cancel, and
the faults: a goal the other side refuses, a server that dies mid-goal, a cancel of a finished goal.

One EMOS run (module fixture): component ``fib`` serves the EMOS action ``/emos_fib``; the test
process is the EMOS action client (``emos.core.services.ActionClient``, as components and
``emos action send_goal`` use it) of the ROS 2 server ``/ros_fib``."""
from __future__ import annotations

import json
import re
import signal
import subprocess
import sys
import threading

import pytest

from emos.core.rpc import RpcError
from emos.core.services import ActionCanceled, ActionClient
from emos.msgs.srv import FibonacciFeedback, FibonacciGoal, FibonacciResult
from tests.ros2.conftest import REPO, Peer, free_domains
from tests.runtime.helpers import HANG_S, SystemUnderTest, wait_until

pytestmark = pytest.mark.process

RECIPE = """
import sys, time
sys.path.insert(0, {repo!r})
from emos.actors.ros2 import Ros2BridgeComponent, Ros2BridgeConfig
from emos.msgs.srv import FibonacciFeedback, FibonacciGoal, FibonacciResult


def fibonacci(handle):
    # The EMOS action server: refuses a negative order, 0.1 s per step, honours cancel.
    order = handle.goal.order
    if order < 0:
        raise ValueError(f"order must be >= 0, got {{order}}")
    sequence = [0, 1][:order]
    while len(sequence) < order and not handle.is_cancel_requested:
        sequence.append(sequence[-1] + sequence[-2])
        handle.publish_feedback(FibonacciFeedback(sequence=sequence))
        time.sleep(0.1)
    return FibonacciResult(sequence=sequence)


class Fib(BaseComponent):
    def custom_on_activate(self):
        self.create_action_server("/emos_fib", FibonacciGoal, FibonacciFeedback, FibonacciResult, fibonacci)

    def _execution_step(self):
        self.health_status.set_healthy()


launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[Fib(component_name="fib")])
launcher.add_pkg(components=[Ros2BridgeComponent(config=Ros2BridgeConfig(domain_id={domain}))], package_name="ros2", multiprocessing=True)
launcher.bringup()
"""


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("ros2actions")
    (domain,) = free_domains(1)
    system = SystemUnderTest(tmp, RECIPE.format(repo=str(REPO), domain=domain))
    system.domain = domain
    try:
        system.wait_up(components=["fib", "ros2_bridge"])
        yield system
    finally:
        code = system.stop()
        print(system.output()[-3000:])
    assert code == 0
    assert system.leftovers() == []


def lines(system: SystemUnderTest, pattern: str) -> list[str]:
    return [line for line in system.output().splitlines() if re.search(pattern, line)]


def bridged(system: SystemUnderTest, name: str) -> str | None:
    try:
        return json.loads((system.run_dir / "ros2_bridge.json").read_text()).get("actions", {}).get(name)
    except (OSError, ValueError):
        return None


def client_of(system: SystemUnderTest, name: str) -> ActionClient:
    return ActionClient(name, FibonacciGoal, FibonacciFeedback, FibonacciResult, ctx=system.ctx)


def test_a_ros2_client_drives_an_emos_action_server_with_feedback_result_and_cancel(run):
    done = Peer("action.py", run.domain, "client", "/emos_fib", 6)
    assert done.wait_for(lambda line: line.startswith("result "), what="the result") == "result SUCCEEDED 0,1,1,2,3,5"
    assert [line for line in done.lines if line.startswith("feedback ")][-1] == "feedback 0,1,1,2,3,5"
    assert bridged(run, "/emos_fib") == "emos->ros2"
    # Cancel mid-goal: the EMOS goal stops, the ROS 2 client gets CANCELED with the partial
    # sequence; then a cancel of that finished goal is answered ERROR_GOAL_TERMINATED (3).
    canceled = Peer("action.py", run.domain, "client", "/emos_fib", 1000, "--cancel-after", 3, "--cancel-finished")
    assert canceled.wait_for(lambda line: line.startswith("cancel "), what="the cancel answer") == "cancel 0 1"
    result = canceled.wait_for(lambda line: line.startswith("result "), what="the result")
    assert result.startswith("result CANCELED 0,1,1,2,3") and len(result.split()[2].split(",")) < 100
    assert canceled.wait_for(lambda line: line.startswith("cancel-finished "), what="the second cancel") == "cancel-finished 3"


def test_a_goal_the_emos_server_refuses_is_aborted_with_one_line(run):
    refused = Peer("action.py", run.domain, "client", "/emos_fib", -1)
    assert refused.wait_for(lambda line: line.startswith("result "), what="the result") == "result ABORTED "
    wait_until(lambda: lines(run, r"action /emos_fib \(test_msgs/action/Fibonacci\): goal \w+ aborted: .*order must be >= 0"),
               what="the bridge's line naming the action")
    assert run.state("ros2_bridge") == "active"


def test_an_emos_client_drives_a_ros2_action_server_with_feedback_result_and_cancel(run):
    server = Peer("action.py", run.domain, "server", "/ros_fib")
    server.wait_for(lambda line: line == "ready", what="ready")
    wait_until(lambda: bridged(run, "/ros_fib") == "ros2->emos", what="/ros_fib bridged to EMOS")
    client = client_of(run, "/ros_fib")
    feedback: list[list[int]] = []
    result = client.send_goal(FibonacciGoal(order=6), feedback_callback=lambda fb: feedback.append(fb.sequence.tolist()), timeout=HANG_S)
    assert result.sequence.tolist() == [0, 1, 1, 2, 3, 5]
    assert feedback[-1] == [0, 1, 1, 2, 3, 5]
    # Cancel mid-goal: ActionCanceled with the sequence so far; a second cancel of the ended goal is refused.
    third = threading.Event()
    ended: dict = {}

    def send() -> None:
        try:
            ended["result"] = client.send_goal(FibonacciGoal(order=1000), goal_id="g1000", timeout=HANG_S,
                                               feedback_callback=lambda fb: third.set() if len(fb.sequence) >= 4 else None)
        except Exception as exc:
            ended["error"] = exc

    worker = threading.Thread(target=send)
    worker.start()
    assert third.wait(HANG_S)
    assert client.cancel("g1000") is True
    worker.join(HANG_S)
    assert isinstance(ended.get("error"), ActionCanceled), ended
    assert 4 <= len(ended["error"].result.sequence) < 100
    server.wait_for(lambda line: line.startswith("canceled "), what="the ROS 2 server canceling")
    assert client.cancel("g1000") is False
    # `emos action send_goal` reaches it through the bridge component, feedback and result printed.
    sent = subprocess.run([sys.executable, "-m", "emos", "action", "send_goal", "ros2_bridge", "/ros_fib", '{"order": 5}',
                           "--run", run.ctx.run_id], check=False, capture_output=True, text=True, timeout=HANG_S)
    assert sent.returncode == 0, sent.stderr
    assert "goal finished: succeeded" in sent.stdout and "[0, 1, 1, 2, 3]" in sent.stdout.replace("\n", "")
    # A goal the ROS 2 server refuses: an error naming the action.
    with pytest.raises(RpcError, match=r"ROS 2 action /ros_fib \(test_msgs/action/Fibonacci\): goal \w+: the server refused the goal"):
        client.send_goal(FibonacciGoal(order=-1), timeout=HANG_S)
    assert run.state("ros2_bridge") == "active"


def test_a_ros2_action_server_that_dies_mid_goal_fails_the_emos_goal_and_a_new_one_is_used(run):
    server = Peer("action.py", run.domain, "server", "/ros_fib2", "--step", 0.2)
    server.wait_for(lambda line: line == "ready", what="ready")
    wait_until(lambda: bridged(run, "/ros_fib2") == "ros2->emos", what="/ros_fib2 bridged to EMOS")
    client = client_of(run, "/ros_fib2")
    started = threading.Event()
    ended: dict = {}

    def send() -> None:
        try:
            ended["result"] = client.send_goal(FibonacciGoal(order=1000), feedback_callback=lambda fb: started.set(), timeout=HANG_S)
        except Exception as exc:
            ended["error"] = exc

    worker = threading.Thread(target=send)
    worker.start()
    assert started.wait(HANG_S)
    server.stop(signal.SIGTERM)  # rclpy's handler ends it mid-goal: no result is ever sent
    worker.join(HANG_S)
    assert isinstance(ended.get("error"), RpcError) and "the server went away mid-goal" in str(ended["error"]), ended
    wait_until(lambda: lines(run, r"action /ros_fib2 .*went away mid-goal"), what="the line naming the action")
    assert len(lines(run, r"went away mid-goal")) == 1
    # A server of the same name comes back: the bridged action works again.
    again = Peer("action.py", run.domain, "server", "/ros_fib2")
    again.wait_for(lambda line: line == "ready", what="ready")
    assert wait_until(lambda: _try(client, 4), what="a goal to the restarted server").sequence.tolist() == [0, 1, 1, 2]


def _try(client: ActionClient, order: int):
    try:
        return client.send_goal(FibonacciGoal(order=order), timeout=HANG_S)
    except RpcError:  # the new server not matched yet
        return None


def test_an_emos_action_server_killed_mid_goal_aborts_the_ros2_goal_and_the_bridge_goes_on(run):
    long = Peer("action.py", run.domain, "client", "/emos_fib", 1000)
    long.wait_for(lambda line: line.startswith("feedback "), what="feedback")
    pid = run.pid("fib")
    import os

    os.kill(pid, signal.SIGKILL)
    assert long.wait_for(lambda line: line.startswith("result "), what="the result") == "result ABORTED "
    run.wait_new_pid("fib", pid)
    # The restarted component serves again under the same name; ROS 2 clients reach it.
    wait_until(lambda: run.state("fib") == "active", what="fib active again")
    again = Peer("action.py", run.domain, "client", "/emos_fib", 3)
    assert again.wait_for(lambda line: line.startswith("result "), what="the result") == "result SUCCEEDED 0,1,1"
    assert run.state("ros2_bridge") == "active"
