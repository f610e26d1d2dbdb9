"""Sensor faults in a component's publish path, switched on from outside by the chaos suite.

Real sensors fail in ways a process kill does not show: a driver stops publishing (stall) or
publishes slowly, a lidar returns NaN or inf ranges, a scan arrives truncated, a camera repeats
one frame with fresh timestamps (freeze), odometry jumps. The node applies these here, just
before a message enters its ring, so every subscriber sees exactly what a broken sensor would
give it.

Injection is refused unless the run was started with ``EMOS_CHAOS=1`` in its environment (as
``emos chaos run`` does): a production robot cannot be made to lie about its sensors by anyone
who can reach its control socket.
"""
from __future__ import annotations

import os
import time
from typing import Any

import attrs
import numpy as np

from emos.core import control as C
from emos.errors import EmosError

MODES = ("stall", "slow", "nan", "inf", "truncate", "freeze", "jump")
ENV_ENABLE = "EMOS_CHAOS"


class FaultInjectionError(EmosError, ValueError):
    """A fault that cannot be applied here (disabled, unknown mode, wrong message type)."""


def injection_enabled() -> bool:
    return os.environ.get(ENV_ENABLE) == "1"


class PublishFaults:
    """Active faults by topic name. Empty in normal operation (one dict lookup per publish)."""

    def __init__(self) -> None:
        self.active: dict[str, dict[str, Any]] = {}

    def set(self, topic: str, msg_type: type, mode: str, **params: Any) -> dict[str, Any]:
        if not injection_enabled():
            raise FaultInjectionError(f"fault injection is disabled in this run (start it with {ENV_ENABLE}=1, as `emos chaos run` does)")
        if mode not in MODES:
            raise FaultInjectionError(f"unknown sensor fault {mode!r}; modes: {', '.join(MODES)}")
        fields = {f.name for f in attrs.fields(msg_type)} if attrs.has(msg_type) else set()
        needs = {"nan": "ranges", "inf": "ranges", "truncate": "ranges", "jump": "pose"}.get(mode)
        if needs and needs not in fields:
            raise FaultInjectionError(f"sensor fault {mode!r} needs a message with {needs!r}; topic {topic!r} carries {msg_type.__name__}")
        fraction = float(params.get("fraction", 0.3))
        every = int(params.get("every", 4))
        if not 0.0 < fraction <= 1.0 or every < 1:
            raise FaultInjectionError(f"sensor fault parameters out of range: fraction in (0, 1], every >= 1; got {params}")
        self.active[topic] = {"mode": mode, "fraction": fraction, "every": every, "count": 0,
                              "dx": float(params.get("dx", 0.5)), "dy": float(params.get("dy", 0.0)), "since": time.time()}
        return {"topic": topic, "mode": mode}

    def clear(self, topic: str | None = None) -> int:
        if topic is None:
            n = len(self.active)
            self.active.clear()
            return n
        return int(self.active.pop(topic, None) is not None)

    def apply(self, topic: str, msg: Any) -> Any | None:
        """The message to publish instead of ``msg`` (None: publish nothing)."""
        fault = self.active.get(topic)
        if fault is None:
            return msg
        mode = fault["mode"]
        fault["count"] += 1
        if mode == "stall":
            return None
        if mode == "slow":
            return msg if fault["count"] % fault["every"] == 0 else None
        if mode in ("nan", "inf"):
            ranges = np.array(msg.ranges, dtype=np.float32, copy=True)
            n = max(1, int(round(len(ranges) * fault["fraction"])))
            start = (fault["count"] * 37) % max(1, len(ranges))  # a moving blind sector
            idx = (start + np.arange(n)) % max(1, len(ranges))
            ranges[idx] = np.nan if mode == "nan" else np.inf
            return attrs.evolve(msg, ranges=ranges)
        if mode == "truncate":
            keep = max(0, int(len(msg.ranges) * (1.0 - fault["fraction"])))
            changes: dict[str, Any] = {"ranges": np.array(msg.ranges[:keep], dtype=np.float32)}
            if len(getattr(msg, "intensities", ())) > keep:
                changes["intensities"] = np.array(msg.intensities[:keep], dtype=np.float32)
            return attrs.evolve(msg, **changes)
        if mode == "freeze":
            frozen = fault.setdefault("frozen", msg)
            header = getattr(msg, "header", None)
            # The same content with the current stamp: a stuck driver, invisible to staleness checks.
            return attrs.evolve(frozen, header=header) if header is not None else frozen
        if mode == "jump":
            return _jumped(msg, fault["dx"], fault["dy"])
        return msg


def fault_ops(node: Any) -> dict[str, Any]:
    """Control-socket operations ``inject_fault`` and ``clear_fault`` for the chaos suite."""

    faults: PublishFaults = node.publish_faults

    async def inject_fault(req: dict[str, Any], stream: Any) -> dict[str, Any]:
        topic = req.get("topic")
        outputs = {t.name: t for t in node.component.out_topics}
        if not isinstance(topic, str) or topic not in outputs:
            raise FaultInjectionError(f"component {node.name!r} publishes no {topic!r}; its outputs: {', '.join(sorted(outputs)) or 'none'}")
        params = req.get("params") or {}
        if not isinstance(params, dict):
            raise FaultInjectionError("inject_fault expects 'params': a map")
        return faults.set(topic, outputs[topic].msg_type, str(req.get("mode")), **params)

    async def clear_fault(req: dict[str, Any], stream: Any) -> int:
        return faults.clear(req.get("topic"))

    return {C.INJECT_FAULT: inject_fault, C.CLEAR_FAULT: clear_fault}


def _jumped(msg: Any, dx: float, dy: float) -> Any:
    pose_holder = msg.pose  # Odometry.pose is a PoseWithCovariance; PoseStamped.pose a Pose
    pose = pose_holder.pose if hasattr(pose_holder, "pose") else pose_holder
    position = attrs.evolve(pose.position, x=pose.position.x + dx, y=pose.position.y + dy)
    new_pose = attrs.evolve(pose, position=position)
    if hasattr(pose_holder, "pose"):
        return attrs.evolve(msg, pose=attrs.evolve(pose_holder, pose=new_pose))
    return attrs.evolve(msg, pose=new_pose)


__all__ = ["FaultInjectionError", "MODES", "PublishFaults", "fault_ops", "injection_enabled"]
