"""The pose-graph back end, on gtsam.

Why gtsam: a pose graph with robust loop-closure factors is a sparse nonlinear least-squares
problem whose incremental solution (iSAM2: re-linearise and re-eliminate only the part of the
Bayes tree a new factor touches) is hard to get right and fast; gtsam is the maintained
reference implementation (Georgia Tech, BSD licence, wheels on PyPI for every platform we
run), with SE(2) poses, between factors, robust M-estimators (Huber, Cauchy) and
Levenberg-Marquardt built in. Writing our own sparse solver would be slower and less tested.
It is imported lazily: only the Mapper and ``emos bench slam`` need it (the ``nav`` extra).

Nodes are scan poses (key = scan index). Factors: a prior on the first node; between factors
for odometry and scan matching (Gaussian); loop closures (between factors under a robust
kernel, so that one wrong closure that got past the matcher's acceptance cannot pull the whole
graph). :meth:`PoseGraph.update` runs one iSAM2 step on what was added since the last one;
:meth:`PoseGraph.optimize_batch` runs Levenberg-Marquardt on the whole graph (what an offline
map build ends with).
"""
from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["PoseGraph", "gtsam_available"]


def gtsam_available() -> bool:
    try:
        import gtsam  # noqa: F401
    except ImportError:
        return False
    return True


def _gtsam() -> Any:
    try:
        import gtsam
    except ImportError as exc:  # the nav extra is not installed
        raise ImportError("the SLAM back end needs gtsam: pip install 'emos[nav]' (or pip install gtsam)") from exc
    return gtsam


class PoseGraph:
    """An SE(2) pose graph solved with iSAM2 (see the module docstring)."""

    def __init__(self, robust: str = "huber", robust_k: float = 1.345, relinearize_skip: int = 1) -> None:
        if robust not in ("huber", "cauchy"):
            raise ValueError(f"PoseGraph: robust must be 'huber' or 'cauchy', got {robust!r}")
        g = _gtsam()
        self._g = g
        self._robust, self._robust_k = robust, float(robust_k)
        params = g.ISAM2Params()
        params.relinearizeSkip = int(relinearize_skip)
        self._isam = g.ISAM2(params)
        self._new = g.NonlinearFactorGraph()
        self._values = g.Values()
        self._all = g.NonlinearFactorGraph()
        self._initial = g.Values()
        self._estimate: Any = None
        self.nodes = 0
        self.extra_keys: list[int] = []
        self.loop_closures = 0

    def _noise(self, cov: np.ndarray, robust: bool) -> Any:
        g = self._g
        cov = np.asarray(cov, dtype=np.float64).reshape(3, 3)
        cov = 0.5 * (cov + cov.T) + np.eye(3) * 1e-12
        base = g.noiseModel.Gaussian.Covariance(cov)
        if not robust:
            return base
        est = g.noiseModel.mEstimator
        kernel = est.Huber.Create(self._robust_k) if self._robust == "huber" else est.Cauchy.Create(self._robust_k)
        return g.noiseModel.Robust.Create(kernel, base)

    def add_node(self, key: int, initial: np.ndarray) -> None:
        x, y, th = (float(v) for v in initial)
        pose = self._g.Pose2(x, y, th)
        self._values.insert(key, pose)
        self._initial.insert(key, pose)
        self.nodes += 1

    def add_variable(self, key: int, initial: np.ndarray) -> None:
        """A pose that is not a scan node (a submap's frame): solved like a node, not counted in
        ``nodes`` (so ``poses`` and the batch results stay the scans'), kept in ``extra_keys``."""
        pose = self._g.Pose2(*(float(v) for v in initial))
        self._values.insert(key, pose)
        self._initial.insert(key, pose)
        self.extra_keys.append(int(key))

    def add_prior(self, key: int, pose: np.ndarray, cov: np.ndarray) -> None:
        f = self._g.PriorFactorPose2(key, self._g.Pose2(*map(float, pose)), self._noise(cov, False))
        self._new.add(f)
        self._all.add(f)

    def add_between(self, a: int, b: int, measured: np.ndarray, cov: np.ndarray, *, loop: bool = False) -> None:
        """``measured``: pose of node ``b`` in the frame of node ``a``; ``cov`` in ``b``'s frame."""
        f = self._g.BetweenFactorPose2(a, b, self._g.Pose2(*map(float, measured)), self._noise(cov, loop))
        self._new.add(f)
        self._all.add(f)
        self.loop_closures += int(loop)

    def update(self, extra_iterations: int = 0) -> None:
        self._isam.update(self._new, self._values)
        for _ in range(extra_iterations):
            self._isam.update()
        self._new = self._g.NonlinearFactorGraph()
        self._values = self._g.Values()
        self._estimate = self._isam.calculateEstimate()

    def pose(self, key: int) -> np.ndarray:
        p = self._estimate.atPose2(key)
        return np.array([p.x(), p.y(), p.theta()])

    def poses(self, count: int) -> np.ndarray:
        return np.array([self.pose(k) for k in range(count)], dtype=np.float64).reshape(-1, 3)

    def optimize_with(self, extra: list[tuple[int, int, np.ndarray, np.ndarray]], start: np.ndarray,
                      iterations: int = 50) -> np.ndarray:
        """Levenberg-Marquardt on every factor plus ``extra`` between factors ``(a, b, measured,
        information)`` (information in ``b``'s frame, under the robust kernel), from ``start``
        (N, 3); returns (N, 3) poses. ``extra`` is not kept: a refinement pass re-derives its
        factors from the estimate it starts from (``GraphSlam.finish``)."""
        g = self._g
        graph = g.NonlinearFactorGraph(self._all)
        for a, b, measured, info in extra:
            info = 0.5 * (np.asarray(info, dtype=np.float64) + np.asarray(info, dtype=np.float64).T) + np.eye(3) * 1e-9
            est = g.noiseModel.mEstimator
            kernel = est.Huber.Create(self._robust_k) if self._robust == "huber" else est.Cauchy.Create(self._robust_k)
            noise = g.noiseModel.Robust.Create(kernel, g.noiseModel.Gaussian.Information(info))
            graph.add(g.BetweenFactorPose2(int(a), int(b), g.Pose2(*map(float, measured)), noise))
        values = g.Values()
        for k, pose in enumerate(np.asarray(start, dtype=np.float64).reshape(-1, 3)):
            values.insert(k, g.Pose2(*map(float, pose)))
        for k in self.extra_keys:  # submap frames: from the current estimate
            values.insert(k, self._estimate.atPose2(k) if self._estimate is not None else self._initial.atPose2(k))
        params = g.LevenbergMarquardtParams()
        params.setMaxIterations(int(iterations))
        result = g.LevenbergMarquardtOptimizer(graph, values, params).optimize()
        self._estimate = result
        return np.array([[result.atPose2(k).x(), result.atPose2(k).y(), result.atPose2(k).theta()]
                         for k in range(self.nodes)], dtype=np.float64).reshape(-1, 3)

    def optimize_batch(self, iterations: int = 50) -> np.ndarray:
        """Levenberg-Marquardt on every factor, from the iSAM2 estimate; returns (N, 3) poses."""
        g = self._g
        params = g.LevenbergMarquardtParams()
        params.setMaxIterations(int(iterations))
        start = self._estimate if self._estimate is not None else self._initial
        result = g.LevenbergMarquardtOptimizer(self._all, start, params).optimize()
        self._estimate = result
        return np.array([[result.atPose2(k).x(), result.atPose2(k).y(), result.atPose2(k).theta()]
                         for k in range(self.nodes)], dtype=np.float64).reshape(-1, 3)
