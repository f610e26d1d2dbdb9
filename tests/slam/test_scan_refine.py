"""Scan-to-scan refinement of the SLAM graph (``mapping.slam.scan_icp`` and
``GraphSlam.finish`` with ``refine_passes``): point-to-line ICP between two scans, its
information along and across a corridor, and the refinement on a synthetic run."""
from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("gtsam")

from emos.actors.nav.localization import noisy_odometry
from emos.actors.nav.mapping.slam import GraphSlam, SlamParams, ate_rmse
from emos.actors.nav.mapping.slam.scan_icp import IcpScan, icp_match
from emos.actors.nav.mapping.slam.slam import compose_pose, relative_pose
from tests.slam.test_slam import ANGLES, _cast, _points, _room

pytestmark = pytest.mark.unit


def test_icp_recovers_the_relative_pose_of_two_scans() -> None:
    room = _room()
    a, b = np.array([6.0, 4.5, 0.3]), np.array([6.8, 4.1, 0.55])
    ref = IcpScan.build(_points(_cast(room, a, ANGLES), ANGLES))
    src = _points(_cast(room, b, ANGLES), ANGLES)
    truth = relative_pose(a, b)
    r = icp_match(ref, src, truth + np.array([0.15, -0.1, math.radians(3.0)]))
    assert r is not None
    err = relative_pose(truth, r.pose)
    assert math.hypot(err[0], err[1]) < 0.01 and abs(err[2]) < math.radians(0.2), err
    assert r.overlap > 0.8 and r.rms < 0.01


def test_icp_information_is_weak_along_a_corridor_and_strong_across() -> None:
    corridor = np.array([(-50, 0, 50, 0), (-50, 2, 50, 2)], dtype=float)
    a, b = np.array([0.0, 1.0, 0.0]), np.array([0.7, 1.1, 0.05])
    ref = IcpScan.build(_points(_cast(corridor, a, ANGLES, 8.0), ANGLES, 8.0))  # a short-range scanner sees no end
    src = _points(_cast(corridor, b, ANGLES, 8.0), ANGLES, 8.0)
    r = icp_match(ref, src, relative_pose(a, b) + np.array([0.0, 0.05, 0.02]))
    assert r is not None
    assert abs(r.pose[1] - 0.1) < 0.01  # across: found
    # Along the corridor (x of the reference frame) the walls say nothing.
    assert r.information[0, 0] < 1e-3 * r.information[1, 1], r.information


def test_icp_gives_up_without_overlap() -> None:
    room = _room()
    a = np.array([6.0, 4.5, 0.0])
    ref = IcpScan.build(_points(_cast(room, a, ANGLES), ANGLES))
    src = _points(_cast(room, a, ANGLES), ANGLES)
    assert icp_match(ref, src, np.array([30.0, 0.0, 0.0])) is None  # no hit within the gate
    assert icp_match(IcpScan.build(np.zeros((0, 2))), src, np.zeros(3)) is None


def test_refine_parameters_are_validated() -> None:
    with pytest.raises(ValueError):
        SlamParams(refine_min_overlap=1.5)
    with pytest.raises(ValueError):
        SlamParams(refine_passes=-1)
    with pytest.raises(ValueError):
        SlamParams(refine_radius=0.0)
    with pytest.raises(ValueError):
        SlamParams(icp_min_conditioning=1.5)
    with pytest.raises(TypeError):
        SlamParams(icp_polish="yes")  # type: ignore[arg-type]


def _drive(laps: int = 1) -> np.ndarray:
    """Laps of a rectangle inside the room, 0.5 m steps."""
    poses = [np.array([2.0, 1.2, 0.0])]
    for _ in range(laps):
        for length, turn in ((8, math.pi / 2), (6, math.pi / 2), (8, math.pi / 2), (6, math.pi / 2)):
            for k in range(length):
                poses.append(compose_pose(poses[-1], np.array([0.5, 0.0, turn if k == length - 1 else 0.0])))
    return np.array(poses)


def _run(truth: np.ndarray, odom: np.ndarray, **params: object) -> tuple[GraphSlam, np.ndarray]:
    room = _room()
    slam = GraphSlam(SlamParams(max_range=20.0, odom_alphas=(0.02, 0.002, 0.02, 0.002), **params))  # type: ignore[arg-type]
    for i, pose in enumerate(truth):
        slam.add(odom[i], _cast(room, pose, ANGLES), ANGLES)
    return slam, slam.finish()


def test_icp_polish_removes_the_front_ends_bias_on_exact_data() -> None:
    """Exact ranges and exact odometry: the likelihood-field polish alone measures each step
    forward short (hits past a known wall's end are pulled back along it), by 1 to 3 cm; the
    point-to-line polish holds them only across the wall."""
    truth = _drive()[:9]
    plain, _ = _run(truth, truth)
    polished, _ = _run(truth, truth, icp_polish=True)
    err_plain = np.hypot(*(np.array(plain.front)[:, :2] - truth[:, :2]).T)
    err_icp = np.hypot(*(np.array(polished.front)[:, :2] - truth[:, :2]).T)
    assert err_plain.max() > 0.01, err_plain  # the bias this removes
    assert err_icp.max() < 0.003, err_icp


def test_refinement_adds_scan_to_scan_factors_and_keeps_the_trajectory() -> None:
    truth = _drive()
    odom = noisy_odometry(truth, (0.01, 0.001, 0.01, 0.001), seed=4)
    slam, refined = _run(truth, odom, refine_passes=1, icp_polish=True)
    factors = slam._scan_factors(refined)
    assert len(factors) > 2 * len(truth)  # each node has several neighbours
    assert all(j < i for j, i, _, _ in factors)
    assert ate_rmse(refined, truth) < 0.01, ate_rmse(refined, truth)


def test_finish_refines_the_batch_by_default() -> None:
    """``GraphSlam.finish`` (what ``emos map build`` and ``emos bench slam`` end with) runs one
    pass of scan-to-scan refinement by default (it lowered the ATE on the tuning logs:
    docs/slam_notes.md); ``refine_passes=0`` gives the batch alone."""
    truth = _drive()
    odom = noisy_odometry(truth, (0.01, 0.001, 0.01, 0.001), seed=4)
    slam, refined = _run(truth, odom)
    _, batch = _run(truth, odom, refine_passes=0)
    assert slam.params.refine_passes == 1
    assert np.abs(refined - batch).max() > 1e-4  # the refinement moved the poses
    assert ate_rmse(refined, truth) < 0.02, ate_rmse(refined, truth)
