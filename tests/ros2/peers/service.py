"""``service.py DOMAIN server NAME`` serves std_srvs/SetBool (answers success=data, message
'ros:<data>'); ``service.py DOMAIN client NAME`` calls std_srvs/Trigger once the service is
there and prints 'answer <success> <message>'."""
import sys

from _ros import rclpy_ready, say

domain, role, name = int(sys.argv[1]), sys.argv[2], sys.argv[3]
rclpy = rclpy_ready()
from emos.interop.ros2 import env  # noqa: E402

env.prepare_package("std_srvs")
from std_srvs.srv import SetBool, Trigger  # noqa: E402

rclpy.init(domain_id=domain)
node = rclpy.create_node(f"srv_{role}")
try:
    if role == "server":
        def answer(request, response):
            response.success, response.message = request.data, f"ros:{request.data}"
            return response

        srv = node.create_service(SetBool, name, answer)
        say("ready")
        rclpy.spin(node)
    else:
        client = node.create_client(Trigger, name)
        say("ready")
        while not client.wait_for_service(timeout_sec=0.5):
            pass
        future = client.call_async(Trigger.Request())
        rclpy.spin_until_future_complete(node, future, timeout_sec=60)
        result = future.result()
        say("answer", result.success, result.message)
except (KeyboardInterrupt, Exception) as exc:  # SIGINT/SIGTERM: rclpy shut the context down
    say("stopped", type(exc).__name__)
finally:
    node.destroy_node()
    rclpy.try_shutdown()
