"""``BaseComponent``: the unit of execution recipes declare and the supervisor runs.

The object a recipe builds is a *description*: name, inputs, outputs, config, run type. Nothing
heavy happens in ``__init__``. When the component runs (in its own process, or in a thread in
threaded mode) a :class:`~emos.core.node.Node` attaches to it, opens topics, and drives the
lifecycle hooks below. Subclasses override:

- ``_execution_step()``: the main step (Timed: every 1/loop_rate s; Event: on each trigger
  message; Server: ``_main_srv_callback``; ActionServer: ``_main_action_callback``);
- ``custom_on_configure / custom_on_activate / custom_on_deactivate / custom_on_shutdown``:
  open and release resources; return nothing, raise to fail the transition.
"""
from __future__ import annotations

import concurrent.futures
import inspect
import logging
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from emos.config.base import BaseComponentConfig, ComponentRunType
from emos.config.loader import load_into
from emos.core.conventions import check_topics, resolve_config
from emos.core.fallbacks import FallbackHooks
from emos.core.health import Status
from emos.core.lifecycle import LifecycleState
from emos.errors import EmosError
from emos.io.topic import Topic
from emos.transport.limits import check_component_name

if TYPE_CHECKING:
    from emos.core.node import Node

_COMPONENT_NAME_CHARS = set("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789_")


class ComponentError(EmosError, RuntimeError):
    """A component used in a way its state does not allow."""


def _check_topics(component: str, role: str, topics: Sequence[Topic] | None) -> list[Topic]:
    # Plain components declare no types (spec None); subclasses check theirs (emos.core.conventions).
    out = check_topics(component, "", role.rstrip("s"), topics, None)
    names = [t.name for t in out]
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise ValueError(f"component {component!r}: {role} list {', '.join(dupes)} more than once")
    return out


class BaseComponent(FallbackHooks):
    """A lifecycle-managed, health-reporting component (fallback hooks: emos.core.fallbacks)."""

    # Subclasses with Server / ActionServer run types declare their interface types here.
    main_srv_type: tuple[Any, Any] | None = None  # (request type, response type)
    main_action_type: tuple[Any, Any, Any] | None = None  # (goal, feedback, result)
    _status_after_step = True  # publish the status after a step that changed it; the Monitor turns this off (its steps are messages, not work)

    def __init__(
        self,
        component_name: str,
        inputs: Sequence[Topic] | None = None,
        outputs: Sequence[Topic] | None = None,
        config: BaseComponentConfig | None = None,
        config_file: str | None = None,
        trigger: Topic | Sequence[Topic] | float | None = None,
        run_type: ComponentRunType | str | None = None,
        main_srv_name: str | None = None,
        main_action_name: str | None = None,
        **kwargs: Any,
    ) -> None:
        if not isinstance(component_name, str) or not component_name or not set(component_name) <= _COMPONENT_NAME_CHARS or component_name[0].isdigit():
            raise ValueError(f"component_name must be letters, digits and '_', not starting with a digit; got {component_name!r}")
        check_component_name(component_name)
        if kwargs:
            raise TypeError(f"component {component_name!r}: unexpected argument(s) {', '.join(sorted(kwargs))}")
        self.component_name = component_name
        self.node_name = component_name
        if config is None:  # a subclass may have set its config before calling us
            config = getattr(self, "config", None)
        self.config: BaseComponentConfig = resolve_config(component_name, type(self).__name__, config, type(self).config_class())
        self.in_topics = _check_topics(component_name, "inputs", inputs)
        self.out_topics = _check_topics(component_name, "outputs", outputs)
        self.config_file = config_file
        if config_file:
            self._apply_config_file(config_file)
        self.health_status = Status()
        self.status_topic = Topic(name=f"{component_name}/status", msg_type="ComponentStatus")
        self.main_srv_name = main_srv_name or f"{component_name}/service"
        self.main_action_name = main_action_name or f"{component_name}/action"
        self._run_type = ComponentRunType.TIMED
        self._trigger: list[Topic] = []
        self._event_trigger: Any = None
        self.trigger = trigger
        if run_type is not None:
            self.run_type = run_type
        self._node: Node | None = None
        self._logger = logging.getLogger(f"emos.{component_name}")

    # -- configuration --------------------------------------------------------------------------
    @classmethod
    def config_class(cls) -> type[BaseComponentConfig]:
        """The config class this component runs with (subclasses narrow it); a recipe that gives
        no config gets a default instance of it (see emos.core.conventions.resolve_config)."""
        return BaseComponentConfig

    def _apply_config_file(self, path: str) -> None:
        topics = load_into(self.config, path, self.component_name)
        for section, attr in (("inputs", "in_topics"), ("outputs", "out_topics")):
            spec = topics.get(section)
            if not spec:
                continue
            if not isinstance(spec, dict):
                raise ValueError(f"{path}: {self.component_name}.{section} must map keys to topics")
            current = {t.name: t for t in getattr(self, attr)}
            for key, tdef in spec.items():
                if not isinstance(tdef, dict):
                    raise ValueError(f"{path}: {self.component_name}.{section}.{key} must be a mapping with name and msg_type")
                try:
                    topic = Topic(**tdef)
                except Exception as exc:
                    raise ValueError(f"{path}: {self.component_name}.{section}.{key}: {exc}") from exc
                current[topic.name] = topic
            setattr(self, attr, list(current.values()))

    def configure(self, config_file: str) -> None:
        """Reload parameters from a YAML, TOML or JSON file (the ``/**`` section and our own)."""
        self.config_file = config_file
        self._apply_config_file(config_file)

    # -- run type and trigger -------------------------------------------------------------------
    @property
    def run_type(self) -> ComponentRunType:
        return self._run_type

    @run_type.setter
    def run_type(self, value: ComponentRunType | str) -> None:
        run_type = ComponentRunType.parse(value)
        if run_type == ComponentRunType.SERVER and self.main_srv_type is None:
            raise ValueError(f"component {self.component_name!r} ({type(self).__name__}) has no main_srv_type, so it cannot be a Server")
        if run_type == ComponentRunType.ACTION_SERVER and self.main_action_type is None:
            raise ValueError(f"component {self.component_name!r} ({type(self).__name__}) has no main_action_type, so it cannot be an ActionServer")
        self._run_type = run_type

    @property
    def trigger(self) -> list[Topic] | float | None:
        if self._run_type == ComponentRunType.EVENT:
            return self._trigger
        return 1.0 / self.config.loop_rate if self._run_type == ComponentRunType.TIMED else None

    @trigger.setter
    def trigger(self, value: Topic | Sequence[Topic] | float | None) -> None:
        if value is None:
            return
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            if value <= 0:
                raise ValueError(f"component {self.component_name!r}: a timed trigger is a period in seconds > 0, got {value}")
            self.config.loop_rate = 1.0 / float(value)
            self._run_type = ComponentRunType.TIMED
            return
        if getattr(value, "_is_emos_event", False):
            # Runs one step each time the event fires (the Monitor routes it; see emos.events).
            self._event_trigger = value
            self._trigger = []
            self._run_type = ComponentRunType.EVENT
            return
        topics = [value] if isinstance(value, Topic) else list(value)  # type: ignore[arg-type]
        for t in topics:
            if not isinstance(t, Topic):
                raise TypeError(f"component {self.component_name!r}: trigger must be a Topic, a list of Topics or a period in seconds, got {type(t).__name__}")
            if t not in self.in_topics:
                self.in_topics.append(t)
        self._trigger = topics
        self._run_type = ComponentRunType.EVENT

    # -- inside a running component ---------------------------------------------------------------
    @property
    def node(self) -> Node:
        if self._node is None:
            raise ComponentError(f"component {self.component_name!r} is not running; this is only available once it has been brought up")
        return self._node

    def get_logger(self) -> logging.Logger:
        return self._logger

    @property
    def lifecycle_state(self) -> LifecycleState:
        return self._node.state if self._node is not None else LifecycleState.UNCONFIGURED

    def get_input(self, topic: Topic | str) -> Any | None:
        """The latest message received on an input topic (``None`` before the first one)."""
        return self.node.latest(topic)

    def input_age(self, topic: Topic | str) -> float | None:
        """Seconds since the last message on an input, ``None`` if none arrived."""
        return self.node.age(topic)

    def stale_inputs(self) -> list[str]:
        """Inputs with no message, or one older than their ``data_timeout``."""
        return self.node.stale_inputs()

    def publish(self, topic: Topic | str, msg: Any) -> None:
        self.node.publish(topic, msg)

    @property
    def health_status_publisher(self) -> _StatusPublisher:
        """Publishes a status at once, from a callback or another thread, as in the ROS-based
        EMOS: ``self.health_status_publisher.publish(self.health_status())``. The node publishes
        the status by itself otherwise: after a step that changed it, and at ``heartbeat_rate``."""
        return _StatusPublisher(self.node)

    def create_timer(self, period: float, callback: Any) -> Any:
        return self.node.create_timer(period, callback)

    def create_service(self, name: str, request_type: Any, response_type: Any, callback: Any) -> None:
        self.node.add_service(name, request_type, response_type, callback)

    def create_action_server(self, name: str, goal_type: Any, feedback_type: Any, result_type: Any, callback: Any) -> None:
        self.node.add_action_server(name, goal_type, feedback_type, result_type, callback)

    def loan(self, topic: Any, msg_type: type, shape: tuple[int, ...], dtype: Any = None, field: str = "data", **fields: Any) -> Any:
        """``with self.loan("/camera/rgb", Image, shape=(480, 640, 3)) as msg:`` fill ``msg.data``
        in shared memory; it is published when the block ends (ROS 2's and iceoryx2's loaned
        messages). Chaos publish faults do not apply to loaned messages."""
        return self.node.loan(topic, msg_type, shape, dtype, field, **fields)

    def served_interfaces(self) -> list[tuple[str, str, tuple[Any, ...]]]:
        """Services and actions served now by something the component holds rather than by its
        node (the ROS 2 bridge's stand-ins for ROS 2 servers): ``(kind, name, types)``, as
        :meth:`~emos.core.node.Node.interfaces` gives them, so ``emos service list/call`` and
        ``emos action`` find them. Called from the node's control loop: return a snapshot."""
        return []

    def update_parameter(self, param_name: str, new_value: Any, keep_alive: bool = True) -> bool:
        """Set one config parameter (validated); returns whether it was applied."""
        try:
            self.config.update(**{param_name: new_value})
        except Exception as exc:
            self._logger.error("[%s] cannot set %s=%r: %s", self.component_name, param_name, new_value, exc)
            return False
        if self._node is not None:
            self._node.on_config_changed()
        return True

    def update_parameters(self, params_names: list[str], new_values: list[Any], keep_alive: bool = True) -> bool:
        try:
            self.config.update(**dict(zip(params_names, new_values, strict=True)))
        except Exception as exc:
            self._logger.error("[%s] cannot set %s: %s", self.component_name, params_names, exc)
            return False
        if self._node is not None:
            self._node.on_config_changed()
        return True

    @property
    def ui_main_action_input(self) -> Any:
        """This component's main action as an input of the web UI: ``enable_ui(inputs=[c.ui_main_action_input])``."""
        from emos.core.action_input import ActionInput
        from emos.msgs.registry import resolve

        if self.main_action_type is None:
            raise ValueError(f"component {self.component_name!r} ({type(self).__name__}) has no main action (main_action_type)")
        goal, feedback, result = (resolve(t) for t in self.main_action_type)
        return ActionInput(self.main_action_name, goal, feedback, result, self.component_name)

    def action_servers(self) -> dict[str, tuple[Any, Any, Any]]:
        """The action servers this component offers, by name, with their (goal, feedback,
        result) types: the main one; a component serving others (from ``create_action_server``)
        adds them, so ``send_component_action_server_goal`` finds the one a goal is for."""
        return {} if self.main_action_type is None else {self.main_action_name: self.main_action_type}

    # -- hooks for subclasses ----------------------------------------------------------------------
    def custom_on_configure(self) -> None:
        pass

    def custom_on_activate(self) -> concurrent.futures.Future[Any] | None:
        """Start what the component needs to run. A component that can serve only after a slow
        start (a model loading in a worker thread) returns a Future that completes when it can:
        the node reports ACTIVE only then, and meanwhile serves its heartbeat and control socket,
        and keeps the triggering messages that arrive for its first steps."""
        return None

    def custom_on_deactivate(self) -> None:
        pass

    def custom_on_cleanup(self) -> None:
        pass

    def custom_on_shutdown(self) -> None:
        pass

    def custom_on_error(self) -> bool:
        """Called when a transition failed; return True to go back to Unconfigured, False to finalize."""
        return True

    def _execution_step(self, **kwargs: Any) -> None:
        """The main step; the base marks the component healthy."""
        self.health_status.set_healthy()

    def _main_srv_callback(self, request: Any) -> Any:
        raise NotImplementedError(f"{type(self).__name__} declares main_srv_type but does not implement _main_srv_callback")

    def _main_action_callback(self, goal_handle: Any) -> Any:
        raise NotImplementedError(f"{type(self).__name__} declares main_action_type but does not implement _main_action_callback")

    # -- introspection -----------------------------------------------------------------------------
    def _step_accepts_kwargs(self) -> bool:
        params = inspect.signature(self._execution_step).parameters.values()
        return any(p.kind in (p.VAR_KEYWORD, p.KEYWORD_ONLY) or p.default is not p.empty for p in params)

    def __repr__(self) -> str:
        return f"{type(self).__name__}(component_name={self.component_name!r}, run_type={self.run_type.value!r})"


class _StatusPublisher:
    """``component.health_status_publisher``: the component's own status topic, written through
    its node (one writer, the lifecycle state and pid filled in)."""

    __slots__ = ("_node",)

    def __init__(self, node: Node):
        self._node = node

    def publish(self, msg: Any) -> None:
        self._node.publish_status_message(msg)
