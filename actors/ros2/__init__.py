"""The ROS 2 bridge as a supervised component (see :mod:`emos.interop.ros2.bridge` for why a
bridge and not a transport): ``Ros2BridgeComponent``, its config, and the Launcher frontend."""
from emos.actors.ros2.component import Ros2BridgeComponent, Ros2BridgeConfig

__all__ = ["Ros2BridgeComponent", "Ros2BridgeConfig"]
