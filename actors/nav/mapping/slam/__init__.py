"""Graph SLAM for 2D lidar: correlative scan-to-submap matching (``matcher``), a gtsam pose
graph with loop closures (``graph``), the pipeline that joins them (``slam``) and the metrics
a trajectory is judged by (``metrics``). The map is drawn from the optimised trajectory with
``localization.build_reference_map`` (log-odds ray casting) and saved with ``maps.map_yaml``."""
from .grid import LikelihoodGrid, max_tables
from .matcher import CorrelativeMatcher, MatchResult, voxel_filter
from .metrics import align_se2, ate_rmse, rpe_rmse
from .relocalize import MapLocalizer, map_grid
from .slam import GraphSlam, SlamParams, Submap, scan_points
from .store import POSEGRAPH_SUFFIX, PoseGraphFile, PoseGraphFileError, load_posegraph, save_posegraph

__all__ = ["POSEGRAPH_SUFFIX", "CorrelativeMatcher", "GraphSlam", "LikelihoodGrid", "MapLocalizer", "MatchResult",
           "PoseGraphFile", "PoseGraphFileError", "SlamParams", "Submap", "align_se2", "ate_rmse", "load_posegraph",
           "map_grid", "max_tables", "rpe_rmse", "save_posegraph", "scan_points", "voxel_filter"]
