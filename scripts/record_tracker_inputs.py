"""The patrol recipe, with what its Behaviors' mover tracker is fed recorded for an offline replay
(scripts/replay_tracker.py; docs/missions.md, "The robot saw with half its beams").

    TRACKER_RECORD=rec.npz [TRACKER_RECORD_SECONDS=900] EMOS_PATROL_LAPS=20 \\
        EMOS_PATROL_WORLD=house_person emos run scripts/record_tracker_inputs.py

Every ``MoverWatch.update`` call of the Behaviors (scan points in the robot frame, the pose, its
stamp and twist) up to TRACKER_RECORD_SECONDS of simulated time goes to TRACKER_RECORD, saved
every 100 scans and at the end (stop the run with Ctrl-C or SIGTERM once that much is recorded). Only the
Behaviors' watch is recorded: the DriveManager's is the same tracker fed the same scans.
"""
from __future__ import annotations

import os
import runpy

import numpy as np

from emos.actors.nav.components import behaviors as behaviors_module
from emos.actors.nav.controllers import movers as movers_module

OUT = os.environ["TRACKER_RECORD"]
LIMIT = float(os.environ.get("TRACKER_RECORD_SECONDS", "900"))
_calls: list[tuple] = []
_done: list[bool] = []  # non-empty once the recording is complete and saved
_update = movers_module.MoverWatch.update
_configure = behaviors_module.Behaviors.custom_on_configure


def _save() -> None:
    tmp = OUT + ".part.npz"
    np.savez_compressed(tmp, stamp=np.array([c[0] for c in _calls]), pose=np.array([c[2] for c in _calls]),
                        angle_increment=np.array([c[3] for c in _calls]), pose_stamp=np.array([c[4] for c in _calls]),
                        twist=np.array([c[5] for c in _calls]), counts=np.array([len(c[1]) for c in _calls]),
                        points=np.concatenate([c[1] for c in _calls]))
    os.replace(tmp, OUT)


def _recording_update(self, stamp, points, pose, angle_increment=0.0, *, pose_stamp=None, twist=None):
    if getattr(self, "recorded", False) and not _done:
        if stamp > LIMIT:  # the last scans since the last save, once
            _done.append(True)
            _save()
        else:
            _calls.append((float(stamp), np.asarray(points, dtype=float).reshape(-1, 2).copy(),
                           np.asarray(pose, dtype=float)[:3].copy(), float(angle_increment),
                           np.nan if pose_stamp is None else float(pose_stamp),
                           np.zeros(3) if twist is None else np.asarray(twist, dtype=float)[:3].copy()))
            if len(_calls) % 100 == 0:
                _save()
    return _update(self, stamp, points, pose, angle_increment, pose_stamp=pose_stamp, twist=twist)


def _recording_configure(self) -> None:
    _configure(self)
    self._movers.recorded = True


movers_module.MoverWatch.update = _recording_update
behaviors_module.Behaviors.custom_on_configure = _recording_configure
runpy.run_path(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "recipes", "patrol.py"), run_name="__main__")
