"""Multi-object tracking by nearest centroid: ids that persist across frames, pixel velocities.

Each new detection is matched to the closest live track of the same label whose centroid lies
within ``max_distance`` pixels (greedy, closest pairs first); unmatched detections start new
tracks; a track unseen for ``max_age`` seconds is dropped. Cheap and deterministic: the Vision
component's tracker when the model server does not track.
"""
from __future__ import annotations

from collections.abc import Sequence

import attrs
import numpy as np


@attrs.define
class Track:
    id: int
    label: str
    box: np.ndarray
    centroid: np.ndarray
    velocity: np.ndarray
    stamp: float


@attrs.frozen
class TrackingResult:
    ids: np.ndarray          # (n,) int64
    labels: list[str]
    boxes: np.ndarray        # (n, 4)
    centroids: np.ndarray    # (n, 2)
    velocities: np.ndarray   # (n, 2) pixels per second


class CentroidTracker:
    def __init__(self, max_distance: float = 30.0, max_age: float = 1.0) -> None:
        if not max_distance > 0 or not max_age > 0:
            raise ValueError(f"CentroidTracker: max_distance and max_age must be > 0, got {max_distance}, {max_age}")
        self.max_distance = float(max_distance)
        self.max_age = float(max_age)
        self.tracks: dict[int, Track] = {}
        self._next_id = 1

    def update(self, boxes: np.ndarray, labels: Sequence[str], stamp: float) -> TrackingResult:
        boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
        if len(labels) != len(boxes):
            raise ValueError(f"tracker: {len(boxes)} boxes but {len(labels)} labels")
        self.tracks = {i: t for i, t in self.tracks.items() if stamp - t.stamp <= self.max_age}
        centroids = np.column_stack([(boxes[:, 0] + boxes[:, 2]) / 2, (boxes[:, 1] + boxes[:, 3]) / 2]) if len(boxes) else np.zeros((0, 2))
        pairs = []
        for d, c in enumerate(centroids):
            for tid, track in self.tracks.items():
                if track.label == labels[d]:
                    dist = float(np.linalg.norm(c - track.centroid))
                    if dist <= self.max_distance:
                        pairs.append((dist, d, tid))
        assigned: dict[int, int] = {}
        used: set[int] = set()
        for _, d, tid in sorted(pairs):
            if d in assigned or tid in used:
                continue
            assigned[d] = tid
            used.add(tid)
        ids, velocities = [], []
        for d, c in enumerate(centroids):
            match = assigned.get(d)
            if match is None:
                tid, self._next_id = self._next_id, self._next_id + 1
                velocity = np.zeros(2)
            else:
                tid = match
                old = self.tracks[tid]
                dt = stamp - old.stamp
                velocity = (c - old.centroid) / dt if dt > 0 else old.velocity
            self.tracks[tid] = Track(tid, labels[d], boxes[d], c, velocity, stamp)
            ids.append(tid)
            velocities.append(velocity)
        return TrackingResult(np.asarray(ids, dtype=np.int64), list(labels), boxes, centroids.reshape(-1, 2),
                              np.asarray(velocities, dtype=np.float64).reshape(-1, 2))
