"""Navigators for maps nobody gave the robot: lidar obstacle memory with scan matching, the
cost-to-go field as global plan, and the arc sampler (or a path follower) as local control.
A harness (``emos bench barn``) calls ``reset(task)`` then ``step(observation)``."""
from .dynamic import DynamicConfig, DynamicGridNavigator
from .interface import Navigator, NavTask, Observation, Scan
from .mapless import GridNavigator
from .with_controller import NAVCORE_CONTROLLERS, NavCoreNavigator

__all__ = ["DynamicConfig", "DynamicGridNavigator", "GridNavigator", "NAVCORE_CONTROLLERS", "NavCoreNavigator", "NavTask", "Navigator", "Observation", "Scan"]
