"""DriveManager algorithms: safety zones, command limiting and smoothing, recovery maneuvers."""
from .commands import CommandFilter, CommandFilterConfig, interpolate_commands
from .maneuvers import (
    Maneuver,
    free_travel,
    move_backward,
    move_forward,
    move_to_unblock,
    rotate_in_place,
    rotation_is_free,
    trapezoid_profile,
)
from .pipeline import DriveSafety
from .swept import ScanCache, SweptCheck, SweptConfig, SweptFootprint, SweptPoints
from .zones import SafetyZones, SafetyZonesConfig, ZoneCheck

__all__ = [
    "CommandFilter",
    "CommandFilterConfig",
    "DriveSafety",
    "Maneuver",
    "SafetyZones",
    "SafetyZonesConfig",
    "ScanCache",
    "SweptCheck",
    "SweptConfig",
    "SweptFootprint",
    "SweptPoints",
    "ZoneCheck",
    "free_travel",
    "interpolate_commands",
    "move_backward",
    "move_forward",
    "move_to_unblock",
    "rotate_in_place",
    "rotation_is_free",
    "trapezoid_profile",
]
