"""Live exchange with ROS 2 nodes: finding ROS 2 (:mod:`.env`), QoS mapping (:mod:`.qos`) and the
bridge between a run's topics and the ROS 2 graph (:mod:`.bridge`). Nothing here imports rclpy
at module import time."""
