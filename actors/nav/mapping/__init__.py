"""Mapping and localization without a map: an obstacle memory built from lidar hits and
correlative scan matching of each scan against it (odometry drift correction)."""
from .evidence import EvidenceConfig, EvidenceGrid
from .hit_grid import HitGrid
from .memory_mapper import MemoryMapper
from .scan_matching import ScanMatcher, compose, correction_between
from .tracking import ScanTracker, Track, TrackerConfig

__all__ = ["EvidenceConfig", "EvidenceGrid", "HitGrid", "MemoryMapper", "ScanMatcher", "ScanTracker", "Track", "TrackerConfig", "compose",
           "correction_between"]
