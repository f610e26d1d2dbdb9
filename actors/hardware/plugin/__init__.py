"""Robot plugins: one home for the API an OEM implements to run EMOS on its chassis.

* :mod:`.transports`: serial (pyserial), UDP, TCP, and driver/SDK sessions;
* :mod:`.declare`: feedback (device -> topics), commands (topics -> device), heartbeats,
  plugin actions and plugin events;
* :mod:`.component`: :class:`RobotPlugin`, the supervised component that runs them;
* :mod:`.registry`: plugins by name, and the description ``emos robot inspect`` prints.

docs/hardware.md walks through writing one.
"""
from .component import PluginConfig, RobotPlugin
from .declare import Command, Feedback, Heartbeat, PluginEvent, plugin_action
from .transports import DeviceError, SerialTransport, SessionTransport, TcpTransport, Transport, UdpTransport

__all__ = ["Command", "DeviceError", "Feedback", "Heartbeat", "PluginConfig", "PluginEvent", "RobotPlugin",
           "SerialTransport", "SessionTransport", "TcpTransport", "Transport", "UdpTransport", "plugin_action"]
