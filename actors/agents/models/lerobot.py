"""Spec for LeRobot policies (SmolVLA, ACT, Diffusion, Pi0) served by LeRobot's async policy server.

The policy must be told the exact feature schema it was trained with. That schema comes from the
dataset's ``meta/info.json``: ``observation.*`` entries are inputs (``observation.state`` carries
the joint names, image/video entries the cameras), ``action`` is the output.

``dataset_info_file`` is a local path or an http(s) URL, and defining the policy reads neither:
the file is loaded when the component that uses the policy is configured (the VLA does it in its
configure step), so a recipe can be defined, listed and checked without the file or a network.
A URL is read from the local cache first, ``$XDG_CACHE_HOME/emos/lerobot/<host>/<path>``
(``~/.cache/emos/lerobot/...`` by default; :func:`dataset_info_cache_path` gives the exact
file), so an offline robot works from a copy put there. Without a cached copy, configure
downloads the file once into the cache, unless ``HF_HUB_OFFLINE=1`` (the Hugging Face switch for
"no network") says not to try. Neither there nor downloadable: configure fails with an error that
names the URL and the cache file to provide.
"""
from __future__ import annotations

import hashlib
import json
import os
import re
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

import attrs

from emos.config import validators as V
from emos.errors import EmosError

from .base import Model

__all__ = ["LeRobotPolicy", "DatasetInfoUnavailable", "dataset_info_cache_path", "features_from_dataset_info",
           "load_dataset_info"]

MAX_INFO_BYTES = 16 * 2**20  # an info.json is a few kB; a bigger answer is not one
DOWNLOAD_TIMEOUT_S = 30.0


class DatasetInfoUnavailable(EmosError, ValueError):
    """A LeRobot ``dataset_info_file`` that cannot be read: missing, not cached and not
    downloadable, or not a LeRobot info.json. Raised at configure; the message names the file."""

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


def _is_url(source: str) -> bool:
    return source.startswith(("http://", "https://"))


def _cache_root() -> Path:
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache").expanduser() / "emos" / "lerobot"


def dataset_info_cache_path(url: str) -> Path:
    """Where the cached copy of ``url`` lives: ``<cache>/<host>/<path>`` (a query adds a hash),
    each part reduced to safe characters, so the path is readable and stays inside the cache."""
    parts = urlsplit(url)
    segments = [re.sub(r"[^A-Za-z0-9._-]", "_", seg) for seg in [parts.netloc, *parts.path.split("/")]]
    segments = [seg for seg in segments if seg and seg not in (".", "..")] or ["info.json"]
    if parts.query:
        segments[-1] += "-" + hashlib.sha256(parts.query.encode()).hexdigest()[:12]
    return _cache_root().joinpath(*segments)


def _parse(data: bytes, where: str) -> dict[str, Any]:
    try:
        info = json.loads(data)
    except ValueError as exc:
        raise DatasetInfoUnavailable(f"LeRobotPolicy.dataset_info_file: {where} is not valid JSON ({exc})") from None
    try:
        features_from_dataset_info(info)
    except ValueError as exc:
        raise DatasetInfoUnavailable(f"LeRobotPolicy.dataset_info_file: {where}: {exc}") from None
    return info


def _read_local(path: Path, where: str) -> dict[str, Any]:
    try:
        if path.stat().st_size > MAX_INFO_BYTES:
            raise DatasetInfoUnavailable(f"LeRobotPolicy.dataset_info_file: {where} is over {MAX_INFO_BYTES} bytes: not an info.json")
        return _parse(path.read_bytes(), where)
    except OSError as exc:
        raise DatasetInfoUnavailable(f"LeRobotPolicy.dataset_info_file: cannot read {where}: {exc.strerror or exc}") from None


def _download(url: str, cached: Path) -> dict[str, Any]:
    import httpx

    try:
        with httpx.stream("GET", url, timeout=DOWNLOAD_TIMEOUT_S, follow_redirects=True) as response:
            response.raise_for_status()
            body = bytearray()
            for chunk in response.iter_bytes():
                body += chunk
                if len(body) > MAX_INFO_BYTES:
                    raise DatasetInfoUnavailable(f"LeRobotPolicy.dataset_info_file: {url} sent over {MAX_INFO_BYTES} bytes: not an info.json")
    except httpx.HTTPError as exc:
        raise DatasetInfoUnavailable(
            f"LeRobotPolicy.dataset_info_file: {url} is not in the cache ({cached}) and cannot be downloaded "
            f"({type(exc).__name__}: {exc}); put a copy of that file there, or give a local path") from None
    data = bytes(body)
    info = _parse(data, url)
    try:  # keep it for the next start (and for offline ones); a failure to cache is not fatal
        cached.parent.mkdir(parents=True, exist_ok=True)
        partial = cached.with_name(f".{cached.name}.{os.getpid()}.part")
        partial.write_bytes(data)
        os.replace(partial, cached)
    except OSError:
        pass
    return info


def load_dataset_info(source: str) -> dict[str, Any]:
    """The info.json named by ``source`` (a path, or a URL: cached copy, else a download unless
    ``HF_HUB_OFFLINE=1``). Raises :class:`DatasetInfoUnavailable` naming what is missing."""
    if not _is_url(source):
        path = Path(source).expanduser()
        if not path.is_file():
            raise DatasetInfoUnavailable(f"LeRobotPolicy.dataset_info_file: expected an existing info.json path or URL, got {source!r}")
        return _read_local(path, str(path))
    cached = dataset_info_cache_path(source)
    if cached.is_file():
        return _read_local(cached, f"{cached} (the cached copy of {source})")
    if os.environ.get("HF_HUB_OFFLINE", "").strip().lower() in ("1", "true", "yes", "on"):
        raise DatasetInfoUnavailable(
            f"LeRobotPolicy.dataset_info_file: {source} is not in the cache ({cached}) and HF_HUB_OFFLINE is set, so "
            "it is not downloaded; put a copy of that file there, or give a local path")
    return _download(source, cached)


@attrs.define(kw_only=True)
class LeRobotPolicy(Model):
    """A LeRobot policy checkpoint. ``dataset_info_file`` (path or URL of ``info.json``) fills
    ``features``, ``actions``, ``image_keys`` and ``joint_keys`` when :meth:`load_dataset_info`
    runs (at the configure of the component using the policy; defining the policy reads
    nothing); without it the VLA component builds the features from its own config."""

    checkpoint: str = attrs.field(default="lerobot/smolvla_base", validator=attrs.validators.instance_of(str))
    policy_type: str = attrs.field(default="smolvla", validator=attrs.validators.in_(POLICY_TYPES))
    actions_per_chunk: int = attrs.field(default=50, validator=V.int_at_least(1))
    policy_device: str = attrs.field(default="cuda", validator=attrs.validators.in_(("cpu", "cuda", "mps")))
    dataset_info_file: str | None = attrs.field(
        default=None, validator=attrs.validators.optional([attrs.validators.instance_of(str), V.non_empty_str])
    )
    _features: dict = attrs.field(factory=dict)
    _actions: dict | None = attrs.field(default=None)
    _image_keys: list | None = attrs.field(default=None)
    _joint_keys: list | None = attrs.field(default=None)

    @property
    def dataset_info_pending(self) -> bool:
        """A ``dataset_info_file`` is set and not loaded yet (rebuilt from ``to_dict`` after
        loading, the features come along and nothing is pending)."""
        return bool(self.dataset_info_file) and not self._features

    def load_dataset_info(self) -> None:
        """Read ``dataset_info_file`` (once) and fill the features from it. Raises
        :class:`DatasetInfoUnavailable` naming the file or URL (and cache file) when it cannot."""
        if not self.dataset_info_pending:
            return
        assert self.dataset_info_file is not None
        parsed = features_from_dataset_info(load_dataset_info(self.dataset_info_file))
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
        # What a client sends when it initializes the policy (at activation): the features must
        # be known by then, whoever uses the policy.
        self.load_dataset_info()
        return {
            "checkpoint": self.checkpoint,
            "policy_type": self.policy_type,
            "features": self._features,
            "actions_per_chunk": self.actions_per_chunk,
            "device": self.policy_device,
        }
