"""The odometry motion model of AMCL (Thrun, Burgard, Fox, *Probabilistic Robotics*, table 5.6,
as Nav2's ``DifferentialMotionModel`` implements it), vectorised over particles.

A motion between two odometry poses is split into a turn ``rot1`` towards the direction of
travel, a straight line ``trans`` and a turn ``rot2``. Each part gets zero-mean Gaussian noise
whose standard deviation grows with the motion:

    sd(rot1)  = sqrt(alpha1 * rot1^2 + alpha2 * trans^2)
    sd(trans) = sqrt(alpha3 * trans^2 + alpha4 * (rot1^2 + rot2^2))
    sd(rot2)  = sqrt(alpha1 * rot2^2 + alpha2 * trans^2)

``alpha1``: rotation noise from rotation, ``alpha2``: rotation noise from translation (rad^2 per
m^2), ``alpha3``: translation noise from translation, ``alpha4``: translation noise from
rotation (m^2 per rad^2). As in Nav2, a backward move counts its turns modulo pi (a reverse is
not a half turn), and a translation under 1 cm has no ``rot1``.

The same model serves twice: the filter samples it to move its particles, and the benchmark
samples it once along a reference trajectory (:func:`noisy_odometry`) to make the odometry a
real robot would have logged.
"""
from __future__ import annotations

import numpy as np

from emos.geometry import wrap_angle

__all__ = ["odometry_delta", "sample_odometry_motion", "noisy_odometry", "relative_pose", "compose_pose"]


def relative_pose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Pose of ``b`` in the frame of ``a`` (both (..., 3) x, y, theta)."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    dx, dy = b[..., 0] - a[..., 0], b[..., 1] - a[..., 1]
    return np.stack([c * dx + s * dy, -s * dx + c * dy, wrap_angle(b[..., 2] - a[..., 2])], axis=-1)


def compose_pose(a: np.ndarray, d: np.ndarray) -> np.ndarray:
    """``a`` moved by ``d`` given in its own frame (the inverse of :func:`relative_pose`)."""
    a, d = np.asarray(a, dtype=np.float64), np.asarray(d, dtype=np.float64)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    return np.stack([a[..., 0] + c * d[..., 0] - s * d[..., 1], a[..., 1] + s * d[..., 0] + c * d[..., 1],
                     wrap_angle(a[..., 2] + d[..., 2])], axis=-1)


def odometry_delta(p0: np.ndarray, p1: np.ndarray, min_trans: float = 0.01) -> tuple[float, float, float]:
    """(rot1, trans, rot2) of the motion from odometry pose ``p0`` to ``p1``; below
    ``min_trans`` (m) of translation the direction of travel means nothing: no rot1."""
    dx, dy = float(p1[0] - p0[0]), float(p1[1] - p0[1])
    trans = float(np.hypot(dx, dy))
    rot1 = 0.0 if trans < min_trans else float(wrap_angle(float(np.arctan2(dy, dx)) - float(p0[2])))
    rot2 = float(wrap_angle(float(p1[2]) - float(p0[2]) - rot1))
    return rot1, trans, rot2


def _reverse_aware(rot: float) -> float:
    """|rot| with a backward move's half turn taken out (Nav2: min of |rot| and |rot - pi|)."""
    return min(abs(rot), abs(float(wrap_angle(rot - np.pi))))


def sample_odometry_motion(poses: np.ndarray, p0: np.ndarray, p1: np.ndarray, alphas: tuple[float, float, float, float],
                           rng: np.random.Generator, scale: np.ndarray | None = None, min_trans: float = 0.01) -> np.ndarray:
    """Particles ``poses`` (N, 3) moved by the odometry motion ``p0 -> p1`` with the noise of
    the module docstring. ``scale`` (N,): per-particle fraction of the motion to apply (the
    filter's answer to an odometry jump: somewhere between "it slipped" and "it moved")."""
    a1, a2, a3, a4 = alphas
    rot1, trans, rot2 = odometry_delta(p0, p1, min_trans)
    r1n, r2n = _reverse_aware(rot1), _reverse_aware(rot2)
    n = len(poses)
    sd_rot1 = np.sqrt(a1 * r1n * r1n + a2 * trans * trans)
    sd_trans = np.sqrt(a3 * trans * trans + a4 * (r1n * r1n + r2n * r2n))
    sd_rot2 = np.sqrt(a1 * r2n * r2n + a2 * trans * trans)
    k = np.ones(n) if scale is None else scale
    rot1_hat = k * rot1 - rng.normal(0.0, 1.0, n) * sd_rot1
    trans_hat = k * trans - rng.normal(0.0, 1.0, n) * sd_trans
    rot2_hat = k * rot2 - rng.normal(0.0, 1.0, n) * sd_rot2
    heading = poses[:, 2] + rot1_hat
    out = np.empty_like(poses)
    out[:, 0] = poses[:, 0] + trans_hat * np.cos(heading)
    out[:, 1] = poses[:, 1] + trans_hat * np.sin(heading)
    out[:, 2] = wrap_angle(heading + rot2_hat)
    return out


def noisy_odometry(reference: np.ndarray, alphas: tuple[float, float, float, float], seed: int,
                   min_trans: float = 0.1) -> np.ndarray:
    """Odometry (N, 3) a robot following ``reference`` (N, 3) would have measured: each
    increment of the reference is perturbed by one draw of the motion model and the noisy
    increments are chained from the reference's first pose. Seeded: the same (reference,
    alphas, seed) always gives the same odometry.

    ``min_trans`` (m): a step that translates less than this is a turn on the spot (no rot1).
    The model splits a turn with a 2 cm drift into a turn towards the drift (up to 180 deg) and
    a turn back, each with noise proportional to it: a 30 deg turn would get 20 deg of error,
    which no wheel odometry has (the reference logs turn on the spot with a few cm of drift).
    Nav2's filter uses 1 cm; the generator uses 10 cm."""
    ref = np.asarray(reference, dtype=np.float64)
    rng = np.random.default_rng(seed)
    out = np.empty_like(ref)
    out[0] = ref[0]
    for i in range(1, len(ref)):
        # The true motion, re-expressed from the noisy pose: the drift accumulates as it does on
        # a robot, and each step's error depends only on that step's motion.
        true_step = relative_pose(ref[i - 1], ref[i])
        moved = sample_odometry_motion(np.zeros((1, 3)), np.zeros(3), true_step, alphas, rng, min_trans=min_trans)[0]
        out[i] = compose_pose(out[i - 1], moved)
    return out
