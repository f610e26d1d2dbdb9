"""The parameters of the Monte Carlo localizer, with Nav2 AMCL's names and defaults.

Nav2 names the KLD parameters ``pf_err`` and ``pf_z`` (ROS 1 amcl: ``kld_err``, ``kld_z``);
both spellings are accepted by :meth:`AmclParams.of`. Parameters that are not Nav2's are marked.
"""
from __future__ import annotations

import math
from typing import Any

from attrs import define, field, fields

from emos.config.validators import in_, in_range, number

__all__ = ["AmclParams"]

_ALIASES = {"kld_err": "pf_err", "kld_z": "pf_z", "odom_alpha1": "alpha1", "odom_alpha2": "alpha2",
            "odom_alpha3": "alpha3", "odom_alpha4": "alpha4", "laser_max_beams": "max_beams",
            "laser_z_hit": "z_hit", "laser_z_rand": "z_rand", "laser_sigma_hit": "sigma_hit"}


def _alpha() -> Any:
    return field(default=0.2, validator=in_range(min_value=0.0, max_value=100.0))


@define(kw_only=True)
class AmclParams:
    """Monte Carlo localization parameters.

    Odometry model: ``alpha1``..``alpha4`` (see ``localization.motion``). Filter:
    ``min_particles``/``max_particles`` (bounds of the KLD-adaptive particle count), ``pf_err``
    and ``pf_z`` (KLD sampling: the error bound and the normal quantile, used as AMCL uses them),
    ``resample_interval`` (sensor updates between resamplings), ``update_min_d`` (m) and
    ``update_min_a`` (rad): the motion that triggers a sensor update, ``recovery_alpha_slow`` /
    ``recovery_alpha_fast``: decay rates of the long- and short-term average likelihood; when the
    short one drops below the long one, random particles are injected (0 and 0: never).
    Sensor model (likelihood field): ``z_hit``, ``z_rand``, ``sigma_hit`` (m),
    ``laser_likelihood_max_dist`` (m), ``laser_max_range`` / ``laser_min_range`` (m; a reading
    at or beyond the max is no echo; -1: use the scan's own), ``max_beams``.

    Not Nav2's: ``jump_distance`` (m) / ``jump_angle`` (rad): an odometry step larger than this
    between two consecutive odometry poses is treated as a jump (a wheel slip, a reset): logged,
    and the particles spread over anywhere between not moving and moving all of it.
    ``min_ess_fraction``: temper a scan's likelihood (raise it to a power <= 1) so that at
    least this fraction of the particles stays effective (0: never temper, as Nav2).
    ``refine_estimate``: polish the published estimate to the scan's nearest likelihood peak
    (a local search around the particles' mean; the particles are not moved).
    ``initial_cov_xy`` (m^2) / ``initial_cov_yaw`` (rad^2): the spread of an initial pose given
    without covariance (ROS amcl's ``initial_cov_xx``, ``initial_cov_aa``).
    ``field_interpolation``: ``"bilinear"`` (interpolate the likelihood field's distance between
    cell centres) or ``"nearest"`` (Nav2's cell lookup); see ``localization.likelihood``.

    Global localization (not Nav2's; they act only from :meth:`ParticleFilter.global_localization`
    until the search has converged, so tracking from a known pose is unchanged):
    ``converged_weight``: the share of the weight the heaviest hypothesis (cluster of particles)
    must hold for the search to end; until then ``max_particles`` are kept (no KLD shrinking)
    and the likelihood is tempered with ``search_min_ess_fraction`` (as ``min_ess_fraction``);
    from then on the filter tracks as from a known pose (``min_ess_fraction``). 1: the search
    never ends. ``hypothesis_beta``: each scan
    of the search, the ``max_hypotheses`` heaviest hypotheses are scan-matched to their nearest
    likelihood peak (every valid beam) and each one's weight is multiplied by
    ``exp(hypothesis_beta * (its peak - the best peak))`` (log-likelihoods): a near-symmetric
    candidate that fits the scan worse loses weight at once, not over metres of tempered
    scans. 0: off. ``converged_updates``: the search ends only once the same hypothesis (moving
    with the odometry) has held ``converged_weight`` on this many consecutive sensor updates
    (each one a new view: the robot moved ``update_min_d`` or turned ``update_min_a``), so
    that one view of a look-alike place does not end it (default 1: the first such update ends
    it; 3 was measured on the tuning logs and did not help, see ``ParticleFilter._leader_holds``).
    ``converged_travel`` (m): and that hypothesis must have held it over this much odometry
    travel (turns on the spot do not count: they show the scanner no new walls). Default 0
    (off): alone, on intel seed 28, 1 m and 2 m only delayed the end of the search on the same
    wrong place, because the right place had lost its particles at 0.14 m of travel.
    ``search_candidates`` (default 20000): each scan of the search, this many random poses in
    free space are scored on about 30 of the scan's beams; the ``search_climbs`` best are
    scan-matched to their likelihood peaks and each peak that no hypothesis covers and that
    fits within about 23 nats of the best hypothesis's peak becomes a particle; together they
    get at most ``search_inject_share`` of the weight (see ``ParticleFilter._propose``). 0: off.
    Alone they gained nothing (every trial they fixed, another stayed undecided); together
    with the through-wall count below (which scores their candidates too), 407 of 420 fresh
    trials on the tuning logs converged against 396 with the count alone, at about the same
    CPU per scan (the search ends sooner); held out fhw 19/20, orebro 20/20 as before
    (docs/localization.md, "Proposals and the wall count together").
    ``runner_up_nats`` (default 0, off): when the search ends, each other hypothesis whose
    scan-matched peak is within this many nats of the leader's is kept as a runner-up of
    ``runner_up_particles`` particles, beside the filter's cloud (which is unchanged); every
    scan, its peak is compared with the leader's, the gap (capped at ``runner_up_scan_nats`` a
    scan) summed into its deficit; it is dropped once the deficit exceeds ``runner_up_nats``
    and takes over the estimate once it leads by ``runner_up_switch_nats`` (see
    ``ParticleFilter._runner_up_step``). Never active when tracking from a known pose.
    ``search_through_wall_nats``: in the search's comparison of hypotheses, each one's peak
    loses this many nats for every beam that, from that peak, passes through an occupied cell
    more than ``search_through_wall_margin`` (m) short of its end point (``LikelihoodField.
    through_walls``). The likelihood field scores only where beams end, so a look-alike place
    with walls where the robot's beams went straight through fits as well as the robot's place.
    Default 2 (0: off): on 420 fresh seeds of the tuning logs, without proposals, 396 trials
    converged against 390 without the count, on the held-out logs fhw 19/20 and orebro 20/20
    against 17 and 18; 1, 4 and 8 nats lost more on the tuning seeds (docs/localization.md,
    "Beams through walls").
    The proposals (``search_candidates``) take the same count off their candidates' peaks.
    """

    alpha1: float = _alpha()
    alpha2: float = _alpha()
    alpha3: float = _alpha()
    alpha4: float = _alpha()
    min_particles: int = field(default=500, validator=in_range(min_value=1, max_value=10_000_000))
    max_particles: int = field(default=2000, validator=in_range(min_value=1, max_value=10_000_000))
    pf_err: float = field(default=0.05, validator=in_range(min_value=1e-6, max_value=1.0))
    pf_z: float = field(default=0.99, validator=in_range(min_value=0.0, max_value=10.0))
    resample_interval: int = field(default=1, validator=in_range(min_value=1, max_value=1000))
    update_min_d: float = field(default=0.25, validator=in_range(min_value=0.0, max_value=100.0))
    update_min_a: float = field(default=0.2, validator=in_range(min_value=0.0, max_value=2 * math.pi))
    recovery_alpha_slow: float = field(default=0.0, validator=in_range(min_value=0.0, max_value=1.0))
    recovery_alpha_fast: float = field(default=0.0, validator=in_range(min_value=0.0, max_value=1.0))
    z_hit: float = field(default=0.5, validator=in_range(min_value=0.0, max_value=1.0))
    z_rand: float = field(default=0.5, validator=in_range(min_value=0.0, max_value=1.0))
    sigma_hit: float = field(default=0.2, validator=in_range(min_value=1e-4, max_value=100.0))
    laser_likelihood_max_dist: float = field(default=2.0, validator=in_range(min_value=1e-3, max_value=1000.0))
    laser_max_range: float = field(default=100.0)
    laser_min_range: float = field(default=-1.0)
    max_beams: int = field(default=60, validator=in_range(min_value=1, max_value=100_000))
    jump_distance: float = field(default=0.5, validator=in_range(min_value=1e-3, max_value=1e6))
    jump_angle: float = field(default=math.pi / 2, validator=in_range(min_value=1e-3, max_value=1e6))
    refine_estimate: bool = field(default=True)
    min_ess_fraction: float = field(default=0.0, validator=in_range(min_value=0.0, max_value=1.0))
    initial_cov_xy: float = field(default=0.25, validator=in_range(min_value=0.0, max_value=1e6))
    initial_cov_yaw: float = field(default=(math.pi / 12) ** 2, validator=in_range(min_value=0.0, max_value=100.0))
    field_interpolation: str = field(default="bilinear", validator=in_(("bilinear", "nearest")))
    # The search's parameters (not Nav2's): NaN-proof bounds, an int where a count is meant.
    converged_weight: float = field(default=0.95, validator=number(ge=0.5, le=1.0))
    search_min_ess_fraction: float = field(default=0.5, validator=number(ge=0.0, le=1.0))
    hypothesis_beta: float = field(default=0.2, validator=number(ge=0.0, le=10.0))
    max_hypotheses: int = field(default=8, validator=number(ge=1, le=1000, integer=True))
    converged_updates: int = field(default=1, validator=number(ge=1, le=1000, integer=True))
    converged_travel: float = field(default=0.0, validator=number(ge=0.0, le=1000.0))
    search_candidates: int = field(default=20_000, validator=number(ge=0, le=10_000_000, integer=True))
    search_climbs: int = field(default=24, validator=number(ge=1, le=10_000, integer=True))
    search_inject_share: float = field(default=0.05, validator=number(ge=0.0, le=0.5))
    runner_up_nats: float = field(default=0.0, validator=number(ge=0.0, le=1e6))
    runner_up_switch_nats: float = field(default=30.0, validator=number(ge=0.0, le=1e6))
    runner_up_scan_nats: float = field(default=20.0, validator=number(gt=0.0, le=1e6))
    runner_up_particles: int = field(default=300, validator=number(ge=1, le=1_000_000, integer=True))
    search_through_wall_nats: float = field(default=2.0, validator=number(ge=0.0, le=1e6))
    search_through_wall_margin: float = field(default=0.3, validator=number(ge=0.0, le=10.0))

    def __attrs_post_init__(self) -> None:
        if self.min_particles > self.max_particles:
            raise ValueError(f"AmclParams: min_particles ({self.min_particles}) must not exceed max_particles "
                             f"({self.max_particles})")
        if self.z_hit + self.z_rand <= 0:
            raise ValueError("AmclParams: z_hit + z_rand must be > 0 (every scan would be impossible)")
        for name in ("laser_max_range", "laser_min_range"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value)):
                raise ValueError(f"AmclParams.{name}: expected a finite number, got {value!r}")

    @classmethod
    def of(cls, value: Any, where: str = "AmclParams") -> AmclParams:
        """An AmclParams from itself or a dict (Nav2 or ROS 1 names); unknown keys are an error."""
        if isinstance(value, cls):
            return value
        if not isinstance(value, dict):
            raise TypeError(f"{where}: expected AmclParams or a dict of its fields, got {type(value).__name__}")
        known = {f.name for f in fields(cls)}
        out: dict[str, Any] = {}
        for key, v in value.items():
            name = _ALIASES.get(str(key), str(key))
            if name not in known:
                raise ValueError(f"{where}: unknown parameter {key!r}; expected one of {sorted(known)}")
            out[name] = v
        return cls(**out)
