"""Tasks at a waypoint (Nav2's waypoint task executors: WaitAtWaypoint, PhotoAtWaypoint, and
any EMOS ``Action``). A task runs in the WaypointFollower's worker thread, so a long one never
stalls its event loop; it gets a ``TaskContext`` and returns a ``TaskOutcome``."""
from __future__ import annotations

import math
import os
import time
from collections.abc import Callable
from typing import Any

import attrs

from emos.core import clock

__all__ = ["WaypointTask", "WaitAtWaypoint", "ActionAtWaypoint", "PhotoAtWaypoint", "TaskOutcome", "TaskContext"]


@attrs.define(frozen=True)
class TaskOutcome:
    ok: bool
    message: str = ""


@attrs.define
class TaskContext:
    """What a task may use: the waypoint, its index and loop, the follower's latest message of
    a topic (``latest(name)``), a cancel flag, and the run context (component calls)."""

    index: int
    loop: int
    waypoint: tuple[float, float, float]
    latest: Callable[[str], Any]
    cancelled: Callable[[], bool]
    run_ctx: Any = None


class WaypointTask:
    def run(self, ctx: TaskContext) -> TaskOutcome:
        raise NotImplementedError


@attrs.define(frozen=True)
class WaitAtWaypoint(WaypointTask):
    """Stand ``waypoint_pause_duration`` s (the node's clock: simulated under a simulator)."""

    waypoint_pause_duration: float = attrs.field(default=1.0, converter=float)

    def __attrs_post_init__(self) -> None:
        if not math.isfinite(self.waypoint_pause_duration) or self.waypoint_pause_duration < 0:
            raise ValueError(f"WaitAtWaypoint: waypoint_pause_duration must be >= 0 s, got {self.waypoint_pause_duration!r}")

    def run(self, ctx: TaskContext) -> TaskOutcome:
        end = clock.now() + self.waypoint_pause_duration
        while clock.now() < end:
            if ctx.cancelled():
                return TaskOutcome(False, "cancelled")
            time.sleep(0.02)
        return TaskOutcome(True, f"waited {self.waypoint_pause_duration:g} s")


@attrs.define(frozen=True)
class ActionAtWaypoint(WaypointTask):
    """Run an EMOS ``Action``: a component's method runs in that component's process (its
    control socket; e.g. ``Action(method=vision.snapshot)``), a function here. A result of
    False, or an error, fails the task."""

    action: Any
    timeout: float = 30.0

    def __attrs_post_init__(self) -> None:
        from emos.events.action import Action

        if not isinstance(self.action, Action):
            raise TypeError(f"ActionAtWaypoint: action must be an emos Action, got {type(self.action).__name__}")
        if self.action.kind not in ("component", "function"):
            raise ValueError(f"ActionAtWaypoint: {self.action.describe()} is a {self.action.kind} action; "
                             "give a component method or a function")

    def run(self, ctx: TaskContext) -> TaskOutcome:
        a = self.action
        try:
            if a.kind == "component":
                from emos.core import control

                result = control.ControlClient(a.component, ctx.run_ctx, timeout=self.timeout).execute_method(a.method_name, *a.args, **a.kwargs)
            else:
                result = a.method(*a.args, **a.kwargs)
        except Exception as exc:  # noqa: BLE001 - the task's failure, reported with the waypoint
            return TaskOutcome(False, f"{a.describe()} raised {type(exc).__name__}: {exc}")
        if result is False:
            return TaskOutcome(False, f"{a.describe()} returned False")
        return TaskOutcome(True, f"{a.describe()} -> {result!r}"[:200])


@attrs.define(frozen=True)
class PhotoAtWaypoint(WaypointTask):
    """Save the latest image of ``image_topic`` (the follower's ``camera`` input: rgb8, bgr8 or
    mono8) as ``<save_dir>/waypoint_<loop>_<index>.png`` (Nav2's PhotoAtWaypoint)."""

    image_topic: str
    save_dir: str

    def run(self, ctx: TaskContext) -> TaskOutcome:
        import numpy as np

        msg = ctx.latest(self.image_topic)
        if msg is None:
            return TaskOutcome(False, f"no image on {self.image_topic} yet")
        data = np.asarray(msg.data, dtype=np.uint8)
        h, w = int(msg.height), int(msg.width)
        channels = data.size // max(h * w, 1)
        if h * w == 0 or channels not in (1, 3, 4) or data.size != h * w * channels:
            return TaskOutcome(False, f"{self.image_topic}: {w}x{h} image with {data.size} bytes")
        img = data.reshape(h, w, channels) if channels > 1 else data.reshape(h, w)
        if str(getattr(msg, "encoding", "")).startswith("bgr"):
            img = img[:, :, [2, 1, 0, *range(3, channels)]]
        os.makedirs(self.save_dir, exist_ok=True)
        path = os.path.join(self.save_dir, f"waypoint_{ctx.loop}_{ctx.index}.png")
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.image

        matplotlib.image.imsave(path, img, cmap=None if channels > 1 else "gray")
        return TaskOutcome(True, path)
