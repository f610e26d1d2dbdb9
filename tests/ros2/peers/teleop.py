"""``teleop.py DOMAIN VX WZ``: a ROS 2 user's teleop, as a plain rclpy node: publishes
geometry_msgs/Twist (linear.x VX, angular.z WZ) on /cmd_vel at 10 Hz, and listens to
nav_msgs/Odometry on /odom, printing 'odom X Y' for each message it gets (at most 5 a second)."""
import sys
import time

from _ros import msg_class, qos, rclpy_ready, say

domain, vx, wz = int(sys.argv[1]), float(sys.argv[2]), float(sys.argv[3])
rclpy = rclpy_ready()
rclpy.init(domain_id=domain)
node = rclpy.create_node("teleop")
Twist, Odometry = msg_class("geometry_msgs/msg/Twist"), msg_class("nav_msgs/msg/Odometry")
pub = node.create_publisher(Twist, "/cmd_vel", qos("default"))
last = [0.0]


def got(msg):
    if time.monotonic() - last[0] >= 0.2:
        last[0] = time.monotonic()
        say("odom", f"{msg.pose.pose.position.x:.3f}", f"{msg.pose.pose.position.y:.3f}")


def drive():
    cmd = Twist()
    cmd.linear.x, cmd.angular.z = vx, wz
    pub.publish(cmd)


sub = node.create_subscription(Odometry, "/odom", got, qos("default"))
timer = node.create_timer(0.1, drive)
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
