"""Robot drive models: how a commanded twist becomes motion (see ``base.DriveModel``).

- ``ideal``: kinematic, does what it is told within the robot's limits (the old default);
- ``skid-steer``: the calibrated skid-steer Jackal (friction, lag, per-episode yaw gain,
  0.25 s command timeout), the realistic BARN default;
- ``wheeled``: the Jackal on four friction wheels in pybullet dynamics (the reference the
  skid-steer model is calibrated against; slower).
"""
from __future__ import annotations

from collections.abc import Callable
from typing import Any

from .base import DriveModel, twist_between
from .ideal import IdealDrive
from .skid_steer import SkidSteerDrive, SkidSteerParams


def _wheeled(**kwargs: Any) -> DriveModel:
    from .wheeled import WheeledJackal

    return WheeledJackal(**kwargs)


DRIVE_MODELS: dict[str, Callable[..., DriveModel]] = {
    "ideal": IdealDrive,
    "skid-steer": SkidSteerDrive,
    "wheeled": _wheeled,
}


def make_drive(name: str | DriveModel, **kwargs: Any) -> DriveModel:
    """A drive model by name (or the given instance)."""
    if isinstance(name, DriveModel):
        return name
    try:
        factory = DRIVE_MODELS[name]
    except KeyError:
        raise ValueError(f"unknown drive model {name!r}; expected one of {sorted(DRIVE_MODELS)}") from None
    return factory(**kwargs)


__all__ = ["DRIVE_MODELS", "DriveModel", "IdealDrive", "SkidSteerDrive", "SkidSteerParams", "make_drive", "twist_between"]
