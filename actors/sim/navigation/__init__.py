"""Navigation inside the simulator: the Navigator contract and a built-in navigator."""
from .builtin import GridNavigator
from .interface import NavTask, Navigator, Observation

__all__ = ["GridNavigator", "NavTask", "Navigator", "Observation"]
