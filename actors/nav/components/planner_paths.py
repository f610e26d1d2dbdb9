"""Path files and path recording for the :class:`Planner` (its three extra services).

``<name>/save_plan_to_file`` writes the current plan, or the recorded path while recording
(which stops it), as CSV (``x,y,yaw``); ``<name>/load_plan_from_file`` reads one and publishes
it as the plan (the planner stops re-planning to its goal, so the loaded path stays);
``<name>/start_path_recording`` records the robot's location every ``recording_time_step`` s.
"""
from __future__ import annotations

import csv
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from .convert import path_msg
from .interfaces import (
    PathFromToFileRequest,
    PathFromToFileResponse,
    StartPathRecordingRequest,
    StartPathRecordingResponse,
)

__all__ = ["PathFiles", "read_path_csv", "write_path_csv"]


def write_path_csv(path: Path, poses: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(("x", "y", "yaw"))
        writer.writerows(np.asarray(poses, dtype=float).reshape(-1, 3).tolist())


def read_path_csv(path: Path) -> np.ndarray:
    """(N, 3) poses of a path CSV; raises ValueError naming the file and the problem."""
    try:
        with open(path, newline="") as f:
            rows = list(csv.reader(f))
    except OSError as exc:
        raise ValueError(f"cannot read path file {path}: {exc.strerror or exc}") from exc
    if not rows or [c.strip() for c in rows[0][:2]] != ["x", "y"]:
        raise ValueError(f"{path}: expected a CSV with a header 'x,y[,yaw]'")
    try:
        poses = np.array([[float(v) for v in (row + ["0"])[:3]] for row in rows[1:] if row], dtype=float)
    except ValueError as exc:
        raise ValueError(f"{path}: malformed row ({exc})") from exc
    if poses.shape[0] < 2 or not np.all(np.isfinite(poses)):
        raise ValueError(f"{path}: needs at least 2 finite poses, got {poses.shape[0]}")
    return poses


def _file(request: PathFromToFileRequest) -> Path:
    if not request.file_name or "/" in request.file_name:
        raise ValueError(f"file_name must be a plain file name, got {request.file_name!r}")
    return Path(os.path.expanduser(request.file_location or ".")) / request.file_name


class PathFiles:
    """Mixin of the Planner (uses its inputs, config and publishing)."""

    # Shared with the Planner, which sets both when it configures: a loaded path replaces the
    # plan and the goal it was re-planned towards.
    _goal: np.ndarray | None
    last_plan: np.ndarray | None
    _followed: tuple[Any, np.ndarray, Any] | None

    def create_path_services(self) -> None:
        name = self.component_name  # type: ignore[attr-defined]
        self._recording: list | None = None
        self._recording_step = 0.1
        self._recording_timer: Any = None
        self.create_service(f"{name}/save_plan_to_file", PathFromToFileRequest, PathFromToFileResponse, self._save_plan)  # type: ignore[attr-defined]
        self.create_service(f"{name}/load_plan_from_file", PathFromToFileRequest, PathFromToFileResponse, self._load_plan)  # type: ignore[attr-defined]
        self.create_service(f"{name}/start_path_recording", StartPathRecordingRequest, StartPathRecordingResponse, self._start_recording)  # type: ignore[attr-defined]

    def _save_plan(self, request: PathFromToFileRequest) -> PathFromToFileResponse:
        try:
            target = _file(request)
        except ValueError as exc:
            return PathFromToFileResponse(success=False, message=str(exc))
        poses: np.ndarray | None
        if self._recording is not None:
            poses, what = np.asarray(self._recording, dtype=float).reshape(-1, 3), "recorded path"
            self._stop_recording()
        else:
            poses, what = self.last_plan, "plan"
        if poses is None or len(poses) < 2:
            return PathFromToFileResponse(success=False, message=f"no {what} to save (need at least 2 poses)")
        try:
            write_path_csv(target, poses)
        except OSError as exc:
            return PathFromToFileResponse(success=False, message=f"cannot write {target}: {exc.strerror or exc}")
        return PathFromToFileResponse(success=True, message=f"{what} of {len(poses)} poses saved to {target}")

    def _load_plan(self, request: PathFromToFileRequest) -> PathFromToFileResponse:
        try:
            poses = read_path_csv(_file(request))
        except ValueError as exc:
            return PathFromToFileResponse(success=False, message=str(exc))
        self._goal = None  # stop re-planning over the loaded path
        self._followed = None
        self.last_plan = poses
        self.publish(self.get_out_topic("plan"), path_msg(poses, self.config.frames.world))  # type: ignore[attr-defined]
        return PathFromToFileResponse(success=True, message=f"{len(poses)} poses loaded and published")

    def _start_recording(self, request: StartPathRecordingRequest) -> StartPathRecordingResponse:
        step = float(request.recording_time_step)
        if not (math.isfinite(step) and step > 0):
            return StartPathRecordingResponse(success=False, message=f"recording_time_step must be > 0 s, got {step}")
        self._stop_recording()
        self._recording = []
        self._recording_timer = self.create_timer(step, self._record)  # type: ignore[attr-defined]
        return StartPathRecordingResponse(success=True, message=f"recording every {step:g} s until save_plan_to_file")

    def _record(self) -> None:
        state = self.robot_state()  # type: ignore[attr-defined]
        if state is None or self._recording is None:
            return
        pose = state[0]
        if not self._recording or math.dist(self._recording[-1][:2], pose[:2]) > 1e-3:
            self._recording.append(pose.tolist())

    def _stop_recording(self) -> None:
        if self._recording_timer is not None:
            self._recording_timer.cancel()
            self._recording_timer = None
        self._recording = None
