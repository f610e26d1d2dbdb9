"""test_msgs/action/Fibonacci with rclpy's own action machinery.

``action.py DOMAIN server NAME [--step S]``: an ActionServer; refuses goals of a negative order,
publishes the sequence as feedback every ``S`` s, honours cancel (ends CANCELED with the partial
sequence). Prints 'ready', 'goal <order>', 'canceled <n>', 'done <n>'.

``action.py DOMAIN client NAME ORDER [--cancel-after N] [--cancel-finished]``: an ActionClient;
sends one goal once the server is there and prints 'accepted' / 'rejected', 'feedback <seq>',
'cancel <return_code> <goals canceling>' after N feedbacks, 'result <STATUS> <seq>'; with
``--cancel-finished`` it then cancels the finished goal and prints 'cancel-finished <return_code>'.
Sequences print as comma-separated numbers.
"""
import argparse
import threading
import time

from _ros import rclpy_ready, say

parser = argparse.ArgumentParser()
parser.add_argument("domain", type=int)
parser.add_argument("role", choices=["server", "client"])
parser.add_argument("name")
parser.add_argument("order", type=int, nargs="?", default=5)
parser.add_argument("--step", type=float, default=0.1)
parser.add_argument("--cancel-after", type=int, default=0)
parser.add_argument("--cancel-finished", action="store_true")
args = parser.parse_args()

rclpy = rclpy_ready()
from emos.interop.ros2 import env  # noqa: E402

for pkg in ("action_msgs", "test_msgs"):
    env.prepare_package(pkg)
from action_msgs.msg import GoalStatus  # noqa: E402
from rclpy.action import ActionClient, ActionServer, CancelResponse, GoalResponse  # noqa: E402
from rclpy.callback_groups import ReentrantCallbackGroup  # noqa: E402
from rclpy.executors import MultiThreadedExecutor  # noqa: E402
from test_msgs.action import Fibonacci  # noqa: E402

STATUS = {v: k[len("STATUS_"):] for k, v in vars(GoalStatus).items() if k.startswith("STATUS_")}


def seq(values) -> str:
    return ",".join(str(int(v)) for v in values)


rclpy.init(domain_id=args.domain)
node = rclpy.create_node(f"fib_{args.role}")
try:
    if args.role == "server":
        def execute(handle):
            order = handle.request.order
            say("goal", order)
            sequence = [0, 1][:order]
            while len(sequence) < order:
                if handle.is_cancel_requested:
                    handle.canceled()
                    say("canceled", len(sequence))
                    return Fibonacci.Result(sequence=sequence)
                sequence.append(sequence[-1] + sequence[-2] if len(sequence) > 1 else 1)
                handle.publish_feedback(Fibonacci.Feedback(sequence=sequence))
                time.sleep(args.step)
            handle.succeed()
            say("done", len(sequence))
            return Fibonacci.Result(sequence=sequence)

        server = ActionServer(node, Fibonacci, args.name, execute,
                              goal_callback=lambda goal: GoalResponse.REJECT if goal.order < 0 else GoalResponse.ACCEPT,
                              cancel_callback=lambda handle: CancelResponse.ACCEPT, callback_group=ReentrantCallbackGroup())
        executor = MultiThreadedExecutor(num_threads=3)
        executor.add_node(node)
        say("ready")
        executor.spin()
    else:
        client = ActionClient(node, Fibonacci, args.name)
        say("ready")
        while not client.wait_for_server(timeout_sec=0.5):
            pass
        feedbacks = []
        cancel_now = threading.Event()

        def on_feedback(msg):
            feedbacks.append(msg)
            say("feedback", seq(msg.feedback.sequence))
            if args.cancel_after and len(feedbacks) == args.cancel_after:
                cancel_now.set()

        sent = client.send_goal_async(Fibonacci.Goal(order=args.order), feedback_callback=on_feedback)
        rclpy.spin_until_future_complete(node, sent, timeout_sec=60)
        handle = sent.result()
        if not handle.accepted:
            say("rejected")
        else:
            say("accepted")
            result = handle.get_result_async()
            canceled = False
            while not result.done():
                rclpy.spin_once(node, timeout_sec=0.05)
                if cancel_now.is_set() and not canceled:
                    canceled = True
                    answer = handle.cancel_goal_async()
                    rclpy.spin_until_future_complete(node, answer, timeout_sec=30)
                    say("cancel", answer.result().return_code, len(answer.result().goals_canceling))
            say("result", STATUS.get(result.result().status, result.result().status), seq(result.result().result.sequence))
            if args.cancel_finished:
                answer = handle.cancel_goal_async()
                rclpy.spin_until_future_complete(node, answer, timeout_sec=30)
                say("cancel-finished", answer.result().return_code)
        say("end")
except (KeyboardInterrupt, Exception) as exc:  # SIGINT/SIGTERM: rclpy shut the context down
    say("stopped", type(exc).__name__, exc)
finally:
    node.destroy_node()
    rclpy.try_shutdown()
