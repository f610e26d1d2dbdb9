"""Mapping and localization without a map: an obstacle memory built from lidar hits and
correlative scan matching of each scan against it (odometry drift correction)."""
from .hit_grid import HitGrid
from .memory_mapper import MemoryMapper
from .scan_matching import ScanMatcher, compose, correction_between

__all__ = ["HitGrid", "MemoryMapper", "ScanMatcher", "compose", "correction_between"]
