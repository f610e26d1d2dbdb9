"""Rigid transforms and a small transform tree built from ``TFMessage`` batches.

A navigation component that needs where a sensor sits on the robot (e.g. the camera that saw a
goal) reads it from the transform tree the robot publishes on ``/tf``, as ROS nodes do with tf2,
instead of a second copy of the mount in its own config. Transforms are kept as 4x4 homogeneous
matrices; ``TransformTree.lookup(parent, child)`` composes them along the tree, so the frames
need not be parent and child directly (``base_link -> camera_link -> camera/depth`` works).
"""
from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

import numpy as np

__all__ = ["quaternion_matrix", "transform_matrix", "TransformTree"]


def quaternion_matrix(x: float, y: float, z: float, w: float) -> np.ndarray:
    """3x3 rotation of the unit quaternion (x, y, z, w); a zero or non-finite one is a ValueError."""
    q = np.array([x, y, z, w], dtype=np.float64)
    norm = float(np.linalg.norm(q))
    if not (math.isfinite(norm) and norm > 1e-9):
        raise ValueError(f"quaternion {q.tolist()}: expected a finite, non-zero quaternion")
    x, y, z, w = q / norm
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def transform_matrix(translation: Iterable[float], rotation_xyzw: Iterable[float]) -> np.ndarray:
    """4x4 homogeneous transform from a translation (x, y, z) and a quaternion (x, y, z, w)."""
    t = np.asarray(list(translation), dtype=np.float64)
    if t.shape != (3,) or not np.all(np.isfinite(t)):
        raise ValueError(f"translation {t.tolist()}: expected 3 finite numbers")
    out = np.eye(4)
    out[:3, :3] = quaternion_matrix(*rotation_xyzw)
    out[:3, 3] = t
    return out


class TransformTree:
    """The latest transform of every (parent -> child) edge seen in TFMessage batches.

    Each child has one parent (as in tf2); a later transform for the same child replaces the
    earlier one. Lookups compose edges up to a common ancestor.
    """

    def __init__(self) -> None:
        self._edges: dict[str, tuple[str, np.ndarray]] = {}

    def __len__(self) -> int:
        return len(self._edges)

    def set(self, parent: str, child: str, matrix: np.ndarray) -> None:
        if not parent or not child or parent == child:
            raise ValueError(f"transform {parent!r} -> {child!r}: expected two different, non-empty frame names")
        self._edges[child.lstrip("/")] = (parent.lstrip("/"), np.asarray(matrix, dtype=np.float64))

    def update(self, msg: Any) -> list[str]:
        """Add every transform of a TFMessage; returns the problems of those skipped (bad values)."""
        problems = []
        for ts in getattr(msg, "transforms", []):
            tr, rot = ts.transform.translation, ts.transform.rotation
            try:
                self.set(ts.header.frame_id, ts.child_frame_id,
                         transform_matrix((tr.x, tr.y, tr.z), (rot.x, rot.y, rot.z, rot.w)))
            except ValueError as exc:
                problems.append(f"{ts.header.frame_id!r} -> {ts.child_frame_id!r}: {exc}")
        return problems

    def _to_root(self, frame: str) -> tuple[list[str], np.ndarray]:
        """(frames from ``frame`` up to its root, transform root <- frame)."""
        chain, matrix = [frame], np.eye(4)
        while frame in self._edges:
            parent, edge = self._edges[frame]
            matrix = edge @ matrix
            frame = parent
            if frame in chain:  # a cycle: a malformed tree, not a transform
                raise ValueError(f"transform tree has a cycle through {frame!r}")
            chain.append(frame)
        return chain, matrix

    def lookup(self, parent: str, child: str) -> np.ndarray | None:
        """Transform that maps points in ``child`` into ``parent`` (4x4), or None if the two frames
        are not connected in the tree."""
        parent, child = parent.lstrip("/"), child.lstrip("/")
        if parent == child:
            return np.eye(4)
        chain_c, root_from_child = self._to_root(child)
        chain_p, root_from_parent = self._to_root(parent)
        if chain_c[-1] != chain_p[-1]:
            return None
        return np.linalg.inv(root_from_parent) @ root_from_child
