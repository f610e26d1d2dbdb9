"""``talker.py DOMAIN TOPIC pkg/msg/Type RATE_HZ QOS [--prefix P] [--garbage-every N] [--count N]``:
publishes numbered messages (a string type's ``data`` is 'P<n>'; another type gets 'P<n>' as its
header's frame_id). With --garbage-every N every Nth sample is raw bytes that are not valid CDR.
With --count N it stops publishing after N messages and stays on the graph (a latched topic's
last sample is served by a live publisher)."""
import sys
import time

from _ros import msg_class, qos, rclpy_ready, say


def opt(name, default):
    return sys.argv[sys.argv.index(name) + 1] if name in sys.argv else default


domain, topic, ros_type, rate, qos_name = int(sys.argv[1]), sys.argv[2], sys.argv[3], float(sys.argv[4]), sys.argv[5]
prefix, garbage, count = opt("--prefix", ""), int(opt("--garbage-every", 0)), int(opt("--count", 0))
rclpy = rclpy_ready()
rclpy.init(domain_id=domain)
node = rclpy.create_node("talker")
cls = msg_class(ros_type)
pub = node.create_publisher(cls, topic, qos(qos_name))
say("ready")
n = 0
try:
    while rclpy.ok():
        if count == 0 or n < count:
            if garbage and n % garbage == garbage - 1:
                pub.publish(b"\x00\x01\x00\x00\xff")  # a CDR header and one byte: truncated
            else:
                msg = cls()
                if isinstance(getattr(msg, "data", None), str):
                    msg.data = f"{prefix}{n}"
                elif hasattr(msg, "header"):
                    msg.header.frame_id = f"{prefix}{n}"
                pub.publish(msg)
            n += 1
        time.sleep(1.0 / rate)
except (KeyboardInterrupt, Exception):  # SIGINT/SIGTERM: rclpy shut the context down
    pass
finally:
    # Destroyed explicitly: a participant left to the interpreter's exit keeps its Fast DDS
    # shared-memory files in /dev/shm.
    node.destroy_node()
    rclpy.try_shutdown()
