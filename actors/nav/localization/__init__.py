"""Localization: Monte Carlo localization (AMCL family) in pure numpy, and the pieces the
localization benchmark shares with it (CARMEN logs, the odometry noise model, a reference map
from scans at known poses). The ``Localizer`` component (``components/localizer.py``) wires
:class:`ParticleFilter` to topics."""
from .carmen import CarmenLog, CarmenLogError, CarmenScan, beam_angles, is_carmen, read_carmen
from .filter import ParticleFilter, kld_limit, low_variance_resample
from .likelihood import LikelihoodField, select_beams
from .motion import compose_pose, noisy_odometry, odometry_delta, relative_pose, sample_odometry_motion
from .params import AmclParams
from .reference_map import build_reference_map

__all__ = [
    "AmclParams", "CarmenLog", "CarmenLogError", "CarmenScan", "LikelihoodField", "ParticleFilter", "beam_angles",
    "build_reference_map", "compose_pose", "is_carmen", "kld_limit", "low_variance_resample", "noisy_odometry", "odometry_delta",
    "read_carmen", "relative_pose", "sample_odometry_motion", "select_beams",
]
