"""``relay.py DOMAIN IN:OUT:pkg/msg/Type ...``: a plain rclpy node that republishes what it hears.
Each message is deserialized into rclpy's own message class and published again from it, so a
round trip through it checks that ROS 2's type support reads our CDR, and we read its."""
import sys

from _ros import msg_class, qos, rclpy_ready, say

rclpy = rclpy_ready()
rclpy.init(domain_id=int(sys.argv[1]))
node = rclpy.create_node("relay")
keep = []
for spec in sys.argv[2:]:
    src, dst, ros_type = spec.split(":")
    cls = msg_class(ros_type)
    pub = node.create_publisher(cls, dst, qos("default"))
    keep.append(node.create_subscription(cls, src, lambda m, pub=pub: pub.publish(m), qos("default")))
    keep.append(pub)
say("ready")
try:
    rclpy.spin(node)
except (KeyboardInterrupt, Exception):  # SIGINT/SIGTERM: rclpy shut the context down
    pass
finally:
    # Destroyed explicitly: a participant left to the interpreter's exit keeps its Fast DDS
    # shared-memory files in /dev/shm.
    node.destroy_node()
    rclpy.try_shutdown()
