"""Graph SLAM for 2D lidar: correlative scan-to-submap matching (``matcher``), a gtsam pose
graph with loop closures (``graph``), the pipeline that joins them (``slam``) and the metrics
a trajectory is judged by (``metrics``). The map is drawn from the optimised trajectory with
``localization.build_reference_map`` (log-odds ray casting) and saved with ``maps.map_yaml``."""
from .grid import LikelihoodGrid, max_tables
from .matcher import CorrelativeMatcher, MatchResult, voxel_filter
from .metrics import align_se2, ate_rmse, rpe_rmse
from .slam import GraphSlam, SlamParams, Submap, scan_points

__all__ = ["CorrelativeMatcher", "GraphSlam", "LikelihoodGrid", "MatchResult", "SlamParams", "Submap", "align_se2",
           "ate_rmse", "max_tables", "rpe_rmse", "scan_points", "voxel_filter"]
