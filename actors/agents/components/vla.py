"""``VLA``: a vision-language-action policy driving a robot's joints.

An action server (``<component>/vision_language_action``) takes a task instruction. While the
goal runs, the component sends observations (joint states mapped to the policy's dataset names
by ``joint_names_map``, camera frames by ``camera_inputs_map``, and the task) at
``observation_sending_rate``, and publishes the policy's actions, mapped back to the robot's
joint names and capped to its joint limits, at ``action_sending_rate``. The goal ends after
``max_timesteps`` (``set_termination_trigger("timesteps", ...)``), when a stop Event fires
(``set_termination_trigger("event", stop_event=...)``: success, with ``max_timesteps`` as the
failsafe), on cancel, or when the inputs go silent for ``input_timeout`` seconds.
"""
from __future__ import annotations

import asyncio
import time
from typing import Any, ClassVar

import numpy as np
from attrs import define, field

from emos.config import validators as V
from emos.config.base import ComponentRunType
from emos.io.topic import Topic
from emos.msgs import control as C
from emos.msgs import sensor as S
from emos.msgs import std as D

from ..types import ActionChunk, PolicyObservation
from .base import ModelComponent, ModelComponentConfig
from .convert import header_now, image_of
from .vla_interface import VisionLanguageActionFeedback, VisionLanguageActionGoal, VisionLanguageActionResult, joint_limits_from_urdf

ACTION_OUTPUTS = (S.JointState, C.JointTrajectory, C.JointJog, D.Float64MultiArray)
STATE_TYPES = ("positions", "velocities", "efforts")


def _joint_map(instance: Any, attribute: Any, value: Any) -> None:
    if not isinstance(value, dict) or not value:
        raise ValueError("VLAConfig.joint_names_map: expected a non-empty {dataset joint key: robot joint name} dict")
    if not all(isinstance(k, str) and k and isinstance(v, str) and v for k, v in value.items()):
        raise ValueError("VLAConfig.joint_names_map: keys and values must be non-empty strings")
    if len(set(value.values())) != len(value):
        raise ValueError(f"VLAConfig.joint_names_map: two dataset keys map to the same robot joint: {value}")


def _camera_map(instance: Any, attribute: Any, value: Any) -> None:
    if not isinstance(value, dict) or not value:
        raise ValueError("VLAConfig.camera_inputs_map: expected a non-empty {dataset camera name: image Topic} dict")
    for key, topic in value.items():
        if not isinstance(key, str) or not isinstance(topic, Topic) or topic.msg_type not in (S.Image, S.CompressedImage):
            raise ValueError(f"VLAConfig.camera_inputs_map[{key!r}]: expected an Image or CompressedImage Topic, got {topic!r}")


@define(kw_only=True)
class VLAConfig(ModelComponentConfig):
    joint_names_map: dict = field(validator=_joint_map)
    camera_inputs_map: dict = field(validator=_camera_map)
    state_input_type: str = field(default="positions", validator=V.in_(STATE_TYPES))
    action_output_type: str = field(default="positions", validator=V.in_(STATE_TYPES))
    observation_sending_rate: float = field(default=10.0, validator=V.in_range(0.01, 1000.0))
    action_sending_rate: float = field(default=10.0, validator=V.in_range(0.01, 1000.0))
    input_timeout: float = field(default=30.0, validator=V.in_range(0.01, 3600.0))
    robot_urdf_file: str | None = field(default=None)
    #: {robot joint name: (lower, upper)}; overrides the URDF's limits for those joints
    joint_limits: dict | None = field(default=None)
    max_timesteps: int = field(default=100, validator=V.in_range(1, 10_000_000))


class VLA(ModelComponent):
    CONFIG_CLASS: ClassVar[type] = VLAConfig
    ALLOWED_INPUTS: ClassVar[tuple[type, ...]] = (S.JointState, S.Image, S.CompressedImage)
    ALLOWED_OUTPUTS: ClassVar[tuple[type, ...]] = ACTION_OUTPUTS
    main_action_type = (VisionLanguageActionGoal, VisionLanguageActionFeedback, VisionLanguageActionResult)

    def __init__(self, *, inputs: list[Topic], outputs: list[Topic], model_client: Any, config: VLAConfig,
                 component_name: str, **kwargs: Any) -> None:
        if not isinstance(config, VLAConfig):
            raise TypeError(f"component {component_name!r}: VLA needs a VLAConfig with joint_names_map and camera_inputs_map")
        super().__init__(inputs=inputs, outputs=outputs, model_client=model_client, config=config, trigger=None,
                         component_name=component_name, main_action_name=f"{component_name}/vision_language_action", **kwargs)
        self.config: VLAConfig
        self.run_type = ComponentRunType.ACTION_SERVER
        states = [t for t in self.in_topics if t.msg_type is S.JointState]
        if len(states) != 1:
            raise ValueError(f"component {component_name!r}: VLA needs exactly one JointState input (the robot state), got {len(states)}")
        self.state_topic = states[0]
        for key, topic in config.camera_inputs_map.items():
            if topic not in self.in_topics:
                raise ValueError(f"component {component_name!r}: camera {key!r} maps to {topic.name!r}, which is not an input")
        if not self.out_topics:
            raise ValueError(f"component {component_name!r}: VLA needs an output for its joint commands")
        self._check_policy(config)
        self.limits = self._limits(config)
        self.termination: dict[str, Any] = {"mode": "timesteps", "max_timesteps": config.max_timesteps}
        # (Event, [Action]) pairs this component needs the Monitor to run (its stop event); the
        # Launcher's orchestration collects them with the recipe's own events.
        self._own_events_actions: list[tuple[Any, list[Any]]] = []
        self._stop_event_at: float | None = None  # monotonic time of the last stop-event firing

    # ------------------------------------------------------------------ definition-time checks
    def custom_on_configure(self) -> None:
        """Load the policy's dataset info (a file or URL, never read at definition) and check
        it against the maps: a missing file fails the start here, with the file named."""
        super().custom_on_configure()
        policy = self.model_client.model
        if getattr(policy, "dataset_info_pending", False):
            policy.load_dataset_info()
            self._check_policy(self.config)

    def _check_policy(self, config: VLAConfig) -> None:
        policy = self.model_client.model
        if getattr(policy, "dataset_info_pending", False):
            return  # checked at configure, once the dataset info is read
        joint_keys = getattr(policy, "joint_keys", None)
        if joint_keys:
            missing = [k for k in joint_keys if k not in config.joint_names_map]
            if missing:
                raise ValueError(f"component {self.component_name!r}: joint_names_map lacks the policy's joints {missing}")
        image_keys = getattr(policy, "image_keys", None)
        if image_keys:
            cameras = {k.split(".")[-1] for k in image_keys}
            missing = sorted(cameras - set(config.camera_inputs_map))
            if missing:
                raise ValueError(f"component {self.component_name!r}: camera_inputs_map lacks the policy's cameras {missing}")
        if hasattr(policy, "_features") and not policy.features:
            # No dataset info: describe the inputs from our own config, as the policy server needs them.
            names = list(config.joint_names_map)
            policy._features = {"observation.state": {"dtype": "float32", "shape": [len(names)], "names": names},
                                **{f"observation.images.{k}": {"dtype": "image", "shape": [480, 640, 3],
                                                               "names": ["height", "width", "channels"]}
                                   for k in config.camera_inputs_map}}
            policy._actions = {"dtype": "float32", "shape": [len(names)], "names": names}
            policy._joint_keys = names

    def _limits(self, config: VLAConfig) -> dict[str, tuple[float, float]]:
        limits = joint_limits_from_urdf(config.robot_urdf_file) if config.robot_urdf_file else {}
        for name, bounds in (config.joint_limits or {}).items():
            lo, hi = (float(b) for b in bounds)
            if lo > hi:
                raise ValueError(f"VLAConfig.joint_limits[{name!r}]: lower {lo} > upper {hi}")
            limits[name] = (lo, hi)
        if config.robot_urdf_file:
            unknown = [j for j in config.joint_names_map.values() if j not in limits]
            if unknown:
                raise ValueError(f"component {self.component_name!r}: the URDF has no limits for joints {unknown}")
        return limits

    def set_termination_trigger(self, mode: str = "timesteps", max_timesteps: int | None = None, stop_event: Any = None) -> None:
        """How a goal ends: ``"timesteps"`` after ``max_timesteps``; ``"event"`` when
        ``stop_event`` (an :class:`emos.Event`) fires, a success, with ``max_timesteps`` as the
        failsafe (a failure). ``"keyboard"`` needs a terminal and is refused with the reason."""
        if mode not in ("timesteps", "event", "keyboard"):
            raise ValueError(f"component {self.component_name!r}: termination trigger must be 'timesteps', 'event' or 'keyboard', got {mode!r}")
        if mode == "keyboard":
            raise ValueError(f"component {self.component_name!r}: termination by 'keyboard' needs an interactive terminal, "
                             "which components run under the supervisor do not have; use 'timesteps' or 'event', or cancel the goal")
        if mode == "event" and not getattr(stop_event, "_is_emos_event", False):
            raise TypeError(f"component {self.component_name!r}: set_termination_trigger('event') needs stop_event=Event(...), "
                            f"got {type(stop_event).__name__} {stop_event!r}")
        if mode == "timesteps" and stop_event is not None:
            raise ValueError(f"component {self.component_name!r}: stop_event is only used with mode='event'")
        steps = self.config.max_timesteps if max_timesteps is None else max_timesteps
        self.config.max_timesteps = steps  # validated by the config
        self.termination = {"mode": mode, "max_timesteps": steps}
        if mode == "event":
            from emos.events.action import Action

            self._own_events_actions = [(stop_event, [Action(self.stop_on_event)])]
        else:
            self._own_events_actions = []

    def stop_on_event(self) -> None:
        """Run by the Monitor (inside this component) when the stop event fires: the running
        goal, if any, ends as a success at its next timestep."""
        self._stop_event_at = time.monotonic()
        self.get_logger().info("[%s] stop event fired: the running goal, if any, ends", self.component_name)

    def prepare(self, inputs: dict[str, Any], trigger: Topic | None) -> None:
        return None  # an action server: goals, not triggers, drive it

    # ------------------------------------------------------------------ the goal
    def _inputs_now(self) -> dict[str, Any]:
        """The latest inputs, read on the node's event loop (goals run in another thread)."""
        loop = self.node.loop
        assert loop is not None

        async def read() -> dict[str, Any]:
            return self.gather_inputs()

        return asyncio.run_coroutine_threadsafe(read(), loop).result(timeout=5.0)

    def _observation(self, inputs: dict[str, Any], task: str, timestep: int) -> PolicyObservation | str:
        state = inputs.get(self.state_topic.name)
        if state is None:
            return f"no joint state on {self.state_topic.name}"
        values = {"positions": state.position, "velocities": state.velocity, "efforts": state.effort}[self.config.state_input_type]
        observation: dict[str, Any] = {"task": task}
        names = list(state.name)
        for key, joint in self.config.joint_names_map.items():
            if joint not in names or names.index(joint) >= len(values):
                return f"{self.state_topic.name} has no {self.config.state_input_type} for joint {joint!r}"
            observation[key] = float(values[names.index(joint)])
        for key, topic in self.config.camera_inputs_map.items():
            if topic.name not in inputs:
                return f"no image on {topic.name}"
            observation[key] = image_of(inputs[topic.name], topic.name)
        # Wall time on purpose: the LeRobot policy server compares it with its own wall clock
        # (latency, action chunk timing); the robot's time travels as ``timestep``.
        return PolicyObservation(observation=observation, timestep=timestep, timestamp=time.time())

    def _main_action_callback(self, goal_handle: Any) -> VisionLanguageActionResult:
        task = goal_handle.goal.task.strip()
        if not task:
            return VisionLanguageActionResult(success=False, timesteps=0, message="empty task instruction")
        cfg = self.config
        max_steps = self.termination["max_timesteps"]
        period = 1.0 / cfg.action_sending_rate
        observe_every = max(1, round(cfg.action_sending_rate / cfg.observation_sending_rate))
        chunk: ActionChunk | None = None
        step, last_input = 0, time.monotonic()
        started = next_at = time.monotonic()
        by_event = self.termination["mode"] == "event"
        while step < max_steps:
            if goal_handle.is_cancel_requested:
                return VisionLanguageActionResult(success=False, timesteps=step, message="canceled")
            if by_event and self._stop_event_at is not None and self._stop_event_at >= started:
                return VisionLanguageActionResult(success=True, timesteps=step, message=f"stop event after {step} timesteps")
            if step % observe_every == 0 or chunk is None:
                observation = self._observation(self._inputs_now(), task, step)
                if isinstance(observation, str):
                    if time.monotonic() - last_input > cfg.input_timeout:
                        self.health_status.set_fail_system(topic_names=[self.state_topic.name], message=observation)
                        return VisionLanguageActionResult(success=False, timesteps=step, message=observation)
                    time.sleep(min(period, 0.05))
                    continue
                last_input = time.monotonic()

                # this step's observation bound as a default, whenever call_model runs it
                def infer(client: Any, observation: PolicyObservation = observation) -> Any:
                    return client.inference(observation)

                fresh = self.call_model(infer)
                if fresh is not None:
                    chunk = fresh
            action = self._action_for(chunk, step)
            if action is None:  # the policy has produced nothing yet: a timestep is a command sent
                if time.monotonic() - last_input > cfg.input_timeout:
                    return VisionLanguageActionResult(success=False, timesteps=step, message="the policy sent no actions")
                time.sleep(min(period, 0.05))
                continue
            self._publish_action(action)
            goal_handle.publish_feedback(VisionLanguageActionFeedback(timestep=step, message=task))
            step += 1
            self.health_status.set_healthy()
            next_at += period
            time.sleep(max(0.0, next_at - time.monotonic()))
        if by_event:
            return VisionLanguageActionResult(success=False, timesteps=step,
                                              message=f"max_timesteps ({step}) reached before the stop event fired")
        return VisionLanguageActionResult(success=True, timesteps=step, message=f"{step} timesteps")

    @staticmethod
    def _action_for(chunk: ActionChunk | None, step: int) -> np.ndarray | None:
        if chunk is None or len(chunk.actions) == 0:
            return None
        at = np.nonzero(chunk.timesteps == step)[0]
        # The action planned for this timestep, or the chunk's last one if the plan ran out.
        return chunk.actions[int(at[0])] if len(at) else chunk.actions[-1]

    def _publish_action(self, action: np.ndarray) -> None:
        keys = self.model_client.model.joint_keys or list(self.config.joint_names_map)
        if len(action) != len(keys):
            self.health_status.set_fail_algorithm(algorithm_names=[self.model_client_name],
                                                  message=f"the policy sent {len(action)} values for {len(keys)} joints")
            return
        names = [self.config.joint_names_map[k] for k in keys]
        values = np.array([self._cap(n, float(v)) for n, v in zip(names, action)], dtype=np.float64)
        for topic in self.out_topics:
            self.publish(topic, self._command(topic.msg_type, names, values))

    def _cap(self, joint: str, value: float) -> float:
        bounds = self.limits.get(joint)
        return value if bounds is None else min(max(value, bounds[0]), bounds[1])

    def _command(self, msg_type: type, names: list[str], values: np.ndarray) -> Any:
        kind = self.config.action_output_type
        if msg_type is S.JointState:
            empty = np.zeros(0)
            return S.JointState(header=header_now(), name=names,
                                position=values if kind == "positions" else empty,
                                velocity=values if kind == "velocities" else empty,
                                effort=values if kind == "efforts" else empty)
        if msg_type is C.JointTrajectory:
            point_field = {"positions": "positions", "velocities": "velocities", "efforts": "effort"}[kind]
            point = C.JointTrajectoryPoint(**{point_field: values})
            return C.JointTrajectory(header=header_now(), joint_names=names, points=[point])
        if msg_type is C.JointJog:
            return C.JointJog(header=header_now(), joint_names=names,
                              displacements=values if kind == "positions" else np.zeros(0),
                              velocities=values if kind == "velocities" else np.zeros(0))
        return D.Float64MultiArray(data=values)
