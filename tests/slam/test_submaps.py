"""Submap bookkeeping of ``GraphSlam``: periods by scan count (the old rule, unchanged) or by
travel (``submap_travel``), and submap frames as graph variables of their own
(``submap_nodes``)."""
from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

pytest.importorskip("gtsam")

from emos.actors.nav.localization import noisy_odometry
from emos.actors.nav.mapping.slam import CorrelativeMatcher, GraphSlam, SlamParams, ate_rmse
from emos.actors.nav.mapping.slam.matcher import MatchResult
from emos.actors.nav.mapping.slam.slam import compose_pose

from .test_slam import ANGLES, _cast, _room

pytestmark = pytest.mark.unit


def _line(steps: int, step: float) -> np.ndarray:
    return np.array([[1.5 + step * k, 4.5, 0.0] for k in range(steps)])


def _slam(truth: np.ndarray, odom: np.ndarray, **params: object) -> GraphSlam:
    room = _room()
    slam = GraphSlam(SlamParams(max_range=20.0, **params))  # type: ignore[arg-type]
    for i, pose in enumerate(truth):
        slam.add(odom[i], _cast(room, pose, ANGLES), ANGLES)
    return slam


def test_count_rule_is_unchanged() -> None:
    truth = _line(25, 0.3)
    slam = _slam(truth, truth, scans_per_submap=4, submap_nodes=False)  # the old graph layout too
    assert [s.anchor for s in slam.submaps] == list(range(0, 25, 4))
    assert all(s.scans == 8 for s in slam.submaps[:-2])  # two periods each
    assert all(s.finished for s in slam.submaps[:-2]) and not any(s.finished for s in slam.submaps[-2:])
    assert all(s.key == s.anchor for s in slam.submaps)


def test_a_submap_period_ends_after_its_travel() -> None:
    """1 m steps and a 2.5 m period: the scan 3 m past the anchor ends it (a new submap every
    fourth scan, not every tenth), and a submap is finished after two periods."""
    truth = _line(10, 1.0)
    slam = _slam(truth, truth, scans_per_submap=10, submap_travel=2.5)
    assert [s.anchor for s in slam.submaps] == [0, 4, 8]
    assert slam.submaps[0].finished and slam.submaps[0].scans == 8


def test_submap_frames_are_graph_variables_of_their_own() -> None:
    """Every submap gets a variable and every matched scan a factor to each submap it went into;
    the trajectory stays the scans' and the batch solves keep working."""
    poses = [np.array([2.0, 1.2, 0.0])]
    for length in (8, 6, 8, 6):
        for k in range(length):
            poses.append(compose_pose(poses[-1], np.array([0.5, 0.0, math.pi / 2 if k == length - 1 else 0.0])))
    truth = np.array(poses)
    odom = noisy_odometry(truth, (0.01, 0.001, 0.01, 0.001), seed=4)
    slam = _slam(truth, odom, submap_nodes=True, refine_passes=1, icp_polish=True)
    assert slam.graph.extra_keys == [s.key for s in slam.submaps]
    assert all(s.key != s.anchor for s in slam.submaps)
    est = slam.finish()
    assert est.shape == truth.shape
    assert ate_rmse(est, truth) < 0.03, ate_rmse(est, truth)
    assert slam.loops  # loop closures find the submaps by their own frames


def test_submap_parameters_are_validated() -> None:
    with pytest.raises(ValueError):
        SlamParams(submap_travel=-1.0)
    with pytest.raises(ValueError):
        SlamParams(match_polish="nearest")
    with pytest.raises(TypeError):
        SlamParams(submap_nodes="yes")  # type: ignore[arg-type]
    with pytest.raises(ValueError):
        SlamParams(densify_gap=-0.1)


class _RecordingMatcher(CorrelativeMatcher):
    """The real matcher, keeping each result (the front end's is the first of a scan's calls)."""

    def __init__(self) -> None:
        super().__init__()
        self.results: list[MatchResult | None] = []

    def match(self, *args: Any, **kwargs: Any) -> MatchResult | None:
        result = super().match(*args, **kwargs)
        self.results.append(result)
        return result


def test_a_scan_in_two_submaps_counts_its_match_once() -> None:
    """With ``submap_nodes`` a matched scan ties to both submaps it went into, at the same
    front-end pose: one measurement. The two factors' information together is the match's
    (its covariance times ``match_cov_scale``, in the node's axes), not twice that."""
    truth = _line(16, 0.3)
    odom = noisy_odometry(truth, (0.01, 0.001, 0.01, 0.001), seed=2)
    params = SlamParams(max_range=20.0, scans_per_submap=4)
    slam = GraphSlam(params)
    slam.matcher = recorder = _RecordingMatcher()
    room = _room()
    for i, pose in enumerate(truth):
        recorder.results.clear()
        slam.add(odom[i], _cast(room, pose, ANGLES), ANGLES)
    i = len(truth) - 1
    assert len(slam._inserted) == 2  # the last scan went into two live submaps
    front = recorder.results[0]
    assert front is not None
    factors = [slam.graph._all.at(k) for k in range(slam.graph._all.size())]
    live = {sm.key for sm in slam._inserted}  # (loop closures tie it to finished submaps too)
    mine = [f for f in factors if len(f.keys()) == 2 and f.keys()[1] == i and f.keys()[0] in live]
    assert len(mine) == 2
    info = sum(f.noiseModel().R().T @ f.noiseModel().R() for f in mine)
    c, s = math.cos(slam.front[i][2]), math.sin(slam.front[i][2])
    rot = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    expected = np.linalg.inv(params.match_cov_scale * rot @ front.covariance @ rot.T)
    np.testing.assert_allclose(info, expected, rtol=1e-6)
