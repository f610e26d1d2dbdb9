"""Spec for LeRobot policies (SmolVLA, ACT, Diffusion, Pi0) served by LeRobot's async policy server.

The policy must be told the exact feature schema it was trained with. That schema comes from the
dataset's ``meta/info.json``: ``observation.*`` entries are inputs (``observation.state`` carries
the joint names, image/video entries the cameras), ``action`` is the output.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import attrs

from emos.config import validators as V

from .base import Model

__all__ = ["LeRobotPolicy", "features_from_dataset_info"]

POLICY_TYPES = ("smolvla", "diffusion", "act", "pi0", "pi05")


def features_from_dataset_info(info: dict[str, Any]) -> dict[str, Any]:
    """Split a LeRobot ``info.json`` into input features, action spec, image keys and joint keys."""
    feats = info.get("features") if isinstance(info, dict) else None
    if not isinstance(feats, dict):
        raise ValueError("LeRobot dataset info: expected a JSON object with a 'features' object")
    inputs = {k: v for k, v in feats.items() if k.startswith("observation.")}
    if "action" not in feats:
        raise ValueError("LeRobot dataset info: expected an 'action' entry in 'features'")
    state = inputs.get("observation.state")
    if not isinstance(state, dict) or not isinstance(state.get("names"), list):
        raise ValueError("LeRobot dataset info: expected 'observation.state' with a 'names' list")
    images = [k for k, v in inputs.items() if isinstance(v, dict) and v.get("dtype") in ("image", "video")]
    return {"features": inputs, "actions": feats["action"], "image_keys": images, "joint_keys": list(state["names"])}


def _load_info(source: str) -> dict[str, Any]:
    if source.startswith(("http://", "https://")):
        import httpx  # a robot with network access fetches the file once, at definition time

        try:
            response = httpx.get(source, timeout=30.0, follow_redirects=True)
            response.raise_for_status()
            return response.json()
        except (httpx.HTTPError, ValueError) as exc:
            raise ValueError(f"LeRobotPolicy.dataset_info_file: cannot fetch {source}: {exc}") from None
    path = Path(source).expanduser()
    if not path.is_file():
        raise ValueError(f"LeRobotPolicy.dataset_info_file: expected an existing info.json path or URL, got {source!r}")
    try:
        return json.loads(path.read_text())
    except ValueError as exc:
        raise ValueError(f"LeRobotPolicy.dataset_info_file: {path} is not valid JSON ({exc})") from None


@attrs.define(kw_only=True)
class LeRobotPolicy(Model):
    """A LeRobot policy checkpoint. ``dataset_info_file`` (path or URL of ``info.json``) fills
    ``features``, ``actions``, ``image_keys`` and ``joint_keys``; without it the VLA component
    builds the features from its own config."""

    checkpoint: str = attrs.field(default="lerobot/smolvla_base", validator=attrs.validators.instance_of(str))
    policy_type: str = attrs.field(default="smolvla", validator=attrs.validators.in_(POLICY_TYPES))
    actions_per_chunk: int = attrs.field(default=50, validator=V.int_at_least(1))
    policy_device: str = attrs.field(default="cuda", validator=attrs.validators.in_(("cpu", "cuda", "mps")))
    dataset_info_file: str | None = attrs.field(
        default=None, validator=attrs.validators.optional(attrs.validators.instance_of(str))
    )
    _features: dict = attrs.field(factory=dict)
    _actions: dict | None = attrs.field(default=None)
    _image_keys: list | None = attrs.field(default=None)
    _joint_keys: list | None = attrs.field(default=None)

    def __attrs_post_init__(self) -> None:
        # Already filled (rebuilt from to_dict in another process): do not fetch again.
        if self.dataset_info_file and not self._features:
            parsed = features_from_dataset_info(_load_info(self.dataset_info_file))
            self._features = parsed["features"]
            self._actions = parsed["actions"]
            self._image_keys = parsed["image_keys"]
            self._joint_keys = parsed["joint_keys"]

    @property
    def features(self) -> dict:
        return self._features

    @property
    def actions(self) -> dict | None:
        return self._actions

    @property
    def image_keys(self) -> list | None:
        return self._image_keys

    @property
    def joint_keys(self) -> list | None:
        return self._joint_keys

    def get_init_params(self) -> dict[str, Any]:
        return {
            "checkpoint": self.checkpoint,
            "policy_type": self.policy_type,
            "features": self._features,
            "actions_per_chunk": self.actions_per_chunk,
            "device": self.policy_device,
        }
