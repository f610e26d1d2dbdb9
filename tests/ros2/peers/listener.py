"""``listener.py DOMAIN TOPIC pkg/msg/Type QOS [--crc]``: prints 'got <data or frame_id> <CDR
length>' per message. With --crc, the frame_id is 'seq:crc32 of data' (an EMOS camera's), and
it prints 'got <seq> ok|corrupt' instead. After 3 s, prints once 'graph <json>' with the topic
names and types and the node names it sees."""
import json
import sys
import time
import zlib

from _ros import msg_class, qos, rclpy_ready, say

domain, topic, ros_type, qos_name = int(sys.argv[1]), sys.argv[2], sys.argv[3], sys.argv[4]
check_crc = "--crc" in sys.argv
rclpy = rclpy_ready()
from rclpy.serialization import serialize_message  # noqa: E402

rclpy.init(domain_id=domain)
node = rclpy.create_node("listener")
cls = msg_class(ros_type)


def got(msg):
    if check_crc:
        seq, _, crc = msg.header.frame_id.partition(":")
        ok = zlib.crc32(bytes(msg.data)) & 0xFFFFFFFF == int(crc)
        say("got", seq, "ok" if ok and len(msg.data) == msg.step * msg.height else "corrupt")
        return
    key = msg.data if isinstance(getattr(msg, "data", None), str) else getattr(getattr(msg, "header", None), "frame_id", "")
    say("got", key or "-", len(serialize_message(msg)))


sub = node.create_subscription(cls, topic, got, qos(qos_name))
say("ready")
report_at = time.monotonic() + 3.0
try:
    while rclpy.ok():
        rclpy.spin_once(node, timeout_sec=0.1)
        if report_at and time.monotonic() > report_at:
            report_at = 0
            say("graph", json.dumps({"topics": node.get_topic_names_and_types(), "nodes": node.get_node_names()}))
except (KeyboardInterrupt, Exception):  # SIGINT/SIGTERM: rclpy shut the context down
    pass
finally:
    # Destroyed explicitly: a participant left to the interpreter's exit keeps its Fast DDS
    # shared-memory files in /dev/shm.
    node.destroy_node()
    rclpy.try_shutdown()
