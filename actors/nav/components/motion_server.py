"""``MotionServer``: step and circle motion tests, and recording of command vs response.

A test sends a known command on ``robot_command`` (best through the DriveManager) and records,
every ``1/loop_rate`` s, the command seen on the ``command`` input (what really went to the
robot) and the measured motion from ``location``. Each test ends in a CSV in ``tests_folder``
and a PNG plot of commanded vs measured velocities. Run types: Timed (run the tests once after
activation), Event (run them when ``run_tests`` receives True), ActionServer
(``MotionRecording``: record what happens for ``duration`` s, no commands sent).

The default topics are Kompass's: the tests go out on ``/control`` (the DriveManager's
``command`` input) and the ``command`` input records ``/cmd_vel`` (the DriveManager's output).
Publishing the tests on ``/cmd_vel`` would put them beside the DriveManager's own commands
(zeros while it has no input) on the robot's topic: the robot would get both.
"""
from __future__ import annotations

import csv
import math
import os
import threading
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from attrs import define, field
from attrs.validators import optional

from emos.config.base import ComponentRunType
from emos.config.validators import in_range
from emos.core import clock
from emos.core.keyed import AllowedTopic
from emos.io.topic import Topic

from .base import NavComponent, NavComponentConfig, rate_field
from .convert import BadInput, pose_of, twist_msg, twist_of, velocity_of
from .interfaces import MotionRecordingFeedback, MotionRecordingGoal, MotionRecordingResult

__all__ = ["MotionServer", "MotionServerConfig", "circle_tests", "plot_recording"]

COLUMNS = ("t", "cmd_vx", "cmd_vy", "cmd_omega", "x", "y", "yaw", "vx", "vy", "omega")


@define(kw_only=True)
class MotionServerConfig(NavComponentConfig):
    """``test_period`` (s) per test. Step test: ``step_test_velocity`` m/s forward for
    ``step_test_duration`` s, then stop for the rest of the period. Circle test (the spec's
    sequence of three, one CSV each): ``circle_forward`` drives ``circle_test_velocity`` m/s
    with ``circle_test_omega`` rad/s, ``circle_inverse`` the negative velocity with the same
    turn rate, ``circle_backward`` both negated (the forward circle driven in reverse). Unset,
    they are half the robot's ``ctrl_vx_limits.max_vel`` / ``ctrl_omega_limits.max_vel``."""

    loop_rate: float = rate_field(10.0)
    test_period: float = field(default=10.0, validator=in_range(min_value=0.1, max_value=3600.0))
    run_step_test: bool = field(default=False)
    run_circle_test: bool = field(default=True)
    step_test_velocity: float = field(default=1.0, validator=in_range(min_value=-100.0, max_value=100.0))
    step_test_duration: float = field(default=5.0, validator=in_range(min_value=0.05, max_value=3600.0))
    circle_test_velocity: float | None = field(default=None, validator=optional(in_range(min_value=-100.0, max_value=100.0)))
    circle_test_omega: float | None = field(default=None, validator=optional(in_range(min_value=-100.0, max_value=100.0)))
    tests_folder: str = field(default="~/.emos/motion_tests")


class MotionServer(NavComponent):
    allowed_inputs: ClassVar[Mapping[str, AllowedTopic]] = {
        "run_tests": AllowedTopic(types=("Bool",), default=Topic(name="/run_tests", msg_type="Bool")),
        "command": AllowedTopic(types=("Twist", "TwistStamped"), default=Topic(name="/cmd_vel", msg_type="Twist")),
        "location": AllowedTopic(types=("Odometry", "PoseStamped", "Pose"), default=Topic(name="/odom", msg_type="Odometry"), required=True),
    }
    allowed_outputs: ClassVar[Mapping[str, AllowedTopic]] = {
        # Kompass's default: the DriveManager's command input, never the robot's own topic.
        "robot_command": AllowedTopic(types=("Twist", "TwistStamped"), default=Topic(name="/control", msg_type="Twist")),
    }
    main_action_type = (MotionRecordingGoal, MotionRecordingFeedback, MotionRecordingResult)
    config: MotionServerConfig

    @classmethod
    def config_class(cls) -> type[MotionServerConfig]:
        return MotionServerConfig

    def custom_on_configure(self) -> None:
        self.default_trigger("run_tests")
        self._queue: list[tuple[str, Any]] = []  # (test name, command at time t)
        self._test: tuple[str, Any, float, list] | None = None
        self._started_once = False
        self.results: list[str] = []
        self._plotters: list[threading.Thread] = []

    def custom_on_activate(self) -> None:
        self.create_timer(1.0 / self.config.loop_rate, self._tick)
        if self.run_type == ComponentRunType.TIMED and not self._started_once:
            self.start_tests()

    # -- tests -------------------------------------------------------------------------------------------
    def start_tests(self) -> bool:
        """Queue the configured tests (an event action may call this too)."""
        cfg = self.config
        if self._test is not None or self._queue:
            return False
        self._started_once = True
        if cfg.run_step_test:
            v, d = cfg.step_test_velocity, cfg.step_test_duration
            self._queue.append(("step", lambda t: (v if t < d else 0.0, 0.0)))
        if cfg.run_circle_test:
            for name, (v, w) in circle_tests(cfg).items():
                self._queue.append((name, lambda t, v=v, w=w: (v, w)))
        return bool(self._queue)

    def _execution_step(self, msg: Any = None, topic: Any = None, **kwargs: Any) -> None:
        if msg is not None and getattr(msg, "data", False):
            self.start_tests()
        if self._test is None and not self._queue:
            self.health_status.set_healthy()

    def _sample(self, t: float) -> list[float] | None:
        loc = self.latest("location")
        if loc is None or (self.age_of("location") or 0.0) > 0.5:
            self.fail_input("location", f"no fresh odometry on {self.topic_name('location')}: the test cannot measure the response")
            return None
        try:
            pose, vel = pose_of(loc), velocity_of(loc)
        except BadInput as exc:
            self.fail_input("location", str(exc))
            return None
        cmd_msg = self.latest("command")
        cmd = np.zeros(3)
        if cmd_msg is not None:
            try:
                cmd = twist_of(cmd_msg)
            except BadInput:
                cmd = np.full(3, math.nan)
        vel = np.full(3, math.nan) if vel is None else vel
        return [t, *cmd.tolist(), *pose.tolist(), *vel.tolist()]

    def _tick(self) -> None:
        if self._test is None:
            if not self._queue:
                return
            name, profile = self._queue.pop(0)
            self._test = (name, profile, clock.now(), [])
            self.get_logger().info("[%s] starting the %s test (%.1f s)", self.component_name, name, self.config.test_period)
        name, profile, t0, rows = self._test
        t = clock.now() - t0  # the node's clock: simulated seconds under a simulator, as the odometry's
        out = self.get_out_topic("robot_command")
        if t >= self.config.test_period:
            if out is not None:
                self.publish(out, twist_msg(np.zeros(3)))
            self._finish(name, rows)
            self._test = None
            if not self._queue:
                self.get_logger().info("[%s] motion tests done, the robot is stopped", self.component_name)
            return
        v, w = profile(t)
        if out is not None:
            self.publish(out, twist_msg(np.array([v, 0.0, w])))
        row = self._sample(t)
        if row is None:  # no odometry: stop the robot and drop the test
            if out is not None:
                self.publish(out, twist_msg(np.zeros(3)))
            self._test, self._queue = None, []
            return
        row[1:4] = [v, 0.0, w] if self.latest("command") is None else row[1:4]
        rows.append(row)

    def _finish(self, name: str, rows: list) -> str:
        folder = Path(os.path.expanduser(self.config.tests_folder))
        folder.mkdir(parents=True, exist_ok=True)
        stem = folder / f"{self.component_name}_{name}_{time.strftime('%Y%m%d-%H%M%S')}"
        csv_path = stem.with_suffix(".csv")
        with open(csv_path, "w", newline="") as f:
            writer = csv.writer(f)
            writer.writerow(COLUMNS)
            writer.writerows(rows)
        # Plotting (and importing matplotlib) takes seconds: never on the event loop.
        worker = threading.Thread(target=self._plot, args=(csv_path, stem.with_suffix(".png"), f"{name} test"),
                                  name=f"{self.component_name}-plot", daemon=True)
        worker.start()
        self._plotters.append(worker)
        self.results.append(str(csv_path))
        self.get_logger().info("[%s] %s test recorded: %s (%d samples)", self.component_name, name, csv_path, len(rows))
        self.health_status.set_healthy()
        return str(csv_path)

    def _plot(self, csv_path: Path, png_path: Path, title: str) -> None:
        try:
            plot_recording(csv_path, png_path, title=title)
        except Exception as exc:  # reported; the CSV is written either way
            self.get_logger().warning("[%s] CSV %s written, plot failed: %s", self.component_name, csv_path, exc)

    def custom_on_shutdown(self) -> None:
        for worker in getattr(self, "_plotters", []):
            worker.join(timeout=10.0)

    # -- MotionRecording action ---------------------------------------------------------------------------
    def _main_action_callback(self, goal_handle: Any) -> MotionRecordingResult:
        goal: MotionRecordingGoal = goal_handle.goal
        if not (goal.duration > 0 and goal.timestep > 0 and math.isfinite(goal.duration)):
            return MotionRecordingResult(success=False, message=f"duration and timestep must be > 0, got {goal.duration}, {goal.timestep}")
        rows: list = []
        t0 = clock.now()
        while (t := clock.now() - t0) < goal.duration and not goal_handle.is_cancel_requested:
            row = self._sample(t)
            if row is not None:
                rows.append(row)
                goal_handle.publish_feedback(MotionRecordingFeedback(samples=len(rows)))
            time.sleep(goal.timestep)
        path = self._finish(goal.name or "recording", rows)
        return MotionRecordingResult(success=bool(rows), message=f"{len(rows)} samples", file=path)


def circle_tests(cfg: MotionServerConfig) -> dict[str, tuple[float, float]]:
    """The circle tests in the order they run: name -> (linear velocity, angular velocity)."""
    v = cfg.circle_test_velocity if cfg.circle_test_velocity is not None else cfg.robot.ctrl_vx_limits.max_vel / 2
    w = cfg.circle_test_omega if cfg.circle_test_omega is not None else cfg.robot.ctrl_omega_limits.max_vel / 2
    return {"circle_forward": (v, w), "circle_inverse": (-v, w), "circle_backward": (-v, -w)}


def plot_recording(csv_path: str | os.PathLike, png_path: str | os.PathLike, title: str = "") -> None:
    """Commanded vs measured linear and angular velocity over time, and the driven path."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError("plots need matplotlib: pip install 'emos[plots]'") from exc
    data = np.genfromtxt(csv_path, delimiter=",", names=True)
    data = np.atleast_1d(data)
    fig, axes = plt.subplots(1, 3, figsize=(14, 4))
    axes[0].plot(data["t"], data["cmd_vx"], label="commanded")
    axes[0].plot(data["t"], data["vx"], label="measured")
    axes[0].set(xlabel="t [s]", ylabel="vx [m/s]", title="linear velocity")
    axes[1].plot(data["t"], data["cmd_omega"], label="commanded")
    axes[1].plot(data["t"], data["omega"], label="measured")
    axes[1].set(xlabel="t [s]", ylabel="omega [rad/s]", title="angular velocity")
    axes[2].plot(data["x"], data["y"])
    axes[2].set(xlabel="x [m]", ylabel="y [m]", title="path", aspect="equal")
    for ax in axes[:2]:
        ax.legend()
        ax.grid(True)
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(png_path, dpi=80)
    plt.close(fig)
