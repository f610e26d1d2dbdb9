"""Keyed inputs and outputs: the Kompass-style topic API of components with fixed roles.

Components with fixed roles (a planner needs a map, a goal and a location; a simulator
publishes odometry, a scan and a camera) declare their topics by *key*, each key with the
message types it accepts, how many topics it takes and a default topic::

    class Planner(KeyedComponent):
        allowed_inputs = {
            "map": AllowedTopic(types=("OccupancyGrid",), default=Topic(name="/map", msg_type="OccupancyGrid")),
            "goal_point": AllowedTopic(types=("PointStamped", "PoseStamped", "Odometry"), ...),
        }

A recipe then rewires one role without restating the others, as in the ROS original::

    planner.inputs(goal_point=Topic(name="/clicked_point", msg_type="PoseStamped"))
    planner.get_out_topic(TopicsKeys.GLOBAL_PLAN)

A wrong key or a topic of a type the key does not accept fails here, at definition time, naming
the component, the key and the accepted types (the rule lives in :mod:`emos.core.conventions`,
shared with the agents' ``ModelComponent``, which declares its topics as lists). The flat
``in_topics`` / ``out_topics`` lists that the node opens are derived from the keyed tables, so
nothing else in the runtime changes.
"""
from __future__ import annotations

import enum
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

from emos.core.component import BaseComponent
from emos.core.conventions import AllowedTopic, check_topics
from emos.errors import EmosError
from emos.io.topic import Topic, normalize_topic_name

__all__ = ["AllowedTopic", "KeyedComponent", "UnknownTopicKey", "key_name"]


class UnknownTopicKey(EmosError, KeyError):
    """A key the component does not have; the message lists the keys it has."""

    def __str__(self) -> str:
        return str(self.args[0])


def key_name(key: Any) -> str:
    """Keys may be plain strings or str enums (``TopicsKeys.GLOBAL_PLAN``)."""
    if isinstance(key, enum.Enum):
        key = key.value
    if not isinstance(key, str):
        raise TypeError(f"topic key must be a string or a TopicsKeys member, got {type(key).__name__} {key!r}")
    return key


class KeyedComponent(BaseComponent):
    """A :class:`BaseComponent` whose topics are declared by key (see the module docstring)."""

    allowed_inputs: ClassVar[Mapping[str, AllowedTopic]] = {}
    allowed_outputs: ClassVar[Mapping[str, AllowedTopic]] = {}
    #: other names a key answers to (``{"map": "global_map"}``): one shared enum of keys can
    #: then name the same role on the component that publishes it and the one that reads it.
    key_aliases: ClassVar[Mapping[str, str]] = {}

    def __init__(
        self,
        component_name: str,
        inputs: Mapping[str, Topic | Sequence[Topic]] | None = None,
        outputs: Mapping[str, Topic | Sequence[Topic]] | None = None,
        **kwargs: Any,
    ) -> None:
        for role, given in (("inputs", inputs), ("outputs", outputs)):
            if given is not None and not isinstance(given, Mapping):
                raise TypeError(
                    f"component {component_name!r} ({type(self).__name__}): {role} are given by key, "
                    f"e.g. {role}={{'{next(iter(self._allowed(role)), 'key')}': Topic(...)}}, "
                    f"or later with .{role}(key=Topic(...)); got {type(given).__name__}"
                )
        self._keyed: dict[str, dict[str, list[Topic]]] = {
            "inputs": self._defaults(self.allowed_inputs),
            "outputs": self._defaults(self.allowed_outputs),
        }
        # The file's inputs/outputs sections are keyed too: apply it once the keyed tables exist.
        config_file = kwargs.pop("config_file", None)
        super().__init__(component_name, **kwargs)
        self._sync_flat_lists()
        if config_file:
            self.configure(config_file)
        if inputs:
            self.inputs(**inputs)
        if outputs:
            self.outputs(**outputs)

    # -- recipe API ------------------------------------------------------------------------------
    def inputs(self, **topics: Topic | Sequence[Topic] | None) -> None:
        """Set the input topic(s) of one or more keys: ``planner.inputs(goal_point=Topic(...))``.
        ``None`` removes an optional input."""
        self._set("inputs", topics)

    def outputs(self, **topics: Topic | Sequence[Topic] | None) -> None:
        """Set the output topic(s) of one or more keys: ``driver.outputs(robot_command=Topic(...))``."""
        self._set("outputs", topics)

    def get_in_topic(self, key: Any) -> Topic | None:
        """The (first) input topic of ``key``, or None when the key has none."""
        topics = self._topics_of("inputs", key)
        return topics[0] if topics else None

    def get_out_topic(self, key: Any) -> Topic | None:
        """The (first) output topic of ``key``, or None when the key has none."""
        topics = self._topics_of("outputs", key)
        return topics[0] if topics else None

    def get_in_topics(self, key: Any) -> list[Topic]:
        return list(self._topics_of("inputs", key))

    def get_out_topics(self, key: Any) -> list[Topic]:
        return list(self._topics_of("outputs", key))

    def in_key_of(self, topic: Topic | str) -> str | None:
        """The input key a topic (or topic name) is wired to, for step code that receives a topic."""
        name = topic.name if isinstance(topic, Topic) else normalize_topic_name(topic)
        for key, topics in self._keyed["inputs"].items():
            if any(t.name == name for t in topics):
                return key
        return None

    def missing_required(self) -> list[str]:
        """Required keys that have no topic (checked by the launcher before bringup)."""
        return [
            f"{role[:-1]} {key!r}"
            for role in ("inputs", "outputs")
            for key, allowed in self._allowed(role).items()
            if allowed.required and not self._keyed[role].get(key)
        ]

    def _apply_config_file(self, path: str) -> None:
        """Parameters as BaseComponent; ``inputs`` / ``outputs`` sections map *keys* to topics
        (``outputs: {odom: {name: /odometry/filtered, msg_type: Odometry}}``), checked like
        ``.inputs()`` / ``.outputs()``."""
        from emos.config.loader import load_into

        topics = load_into(self.config, path, self.component_name)
        for role in ("inputs", "outputs"):
            spec = topics.get(role)
            if not spec:
                continue
            if not isinstance(spec, Mapping):
                raise ValueError(f"{path}: {self.component_name}.{role} must map keys to topics")
            staged: dict[str, list[Topic]] = {}
            for key, tdef in spec.items():
                defs = tdef if isinstance(tdef, list) else [tdef]
                try:
                    staged[key] = [Topic(**d) for d in defs]
                except Exception as exc:
                    raise ValueError(f"{path}: {self.component_name}.{role}.{key}: expected a mapping with name and "
                                     f"msg_type (or a list of them): {exc}") from exc
            try:
                self._set(role, staged)
            except (KeyError, TypeError, ValueError) as exc:
                raise ValueError(f"{path}: {exc}") from exc

    # -- internals -------------------------------------------------------------------------------
    def _allowed(self, role: str) -> Mapping[str, AllowedTopic]:
        return self.allowed_inputs if role == "inputs" else self.allowed_outputs

    @staticmethod
    def _defaults(allowed: Mapping[str, AllowedTopic]) -> dict[str, list[Topic]]:
        out: dict[str, list[Topic]] = {}
        for key, spec in allowed.items():
            default = spec.default
            out[key] = [] if default is None else (list(default) if isinstance(default, list) else [default])
        return out

    def _key(self, role: str, key: Any) -> str:
        name = key_name(key)
        alias = self.key_aliases.get(name)
        return alias if alias is not None and name not in self._allowed(role) and alias in self._allowed(role) else name

    def _topics_of(self, role: str, key: Any) -> list[Topic]:
        name = self._key(role, key)
        if name not in self._keyed[role]:
            raise UnknownTopicKey(
                f"component {self.component_name!r} ({type(self).__name__}) has no {role[:-1]} key {name!r}; "
                f"its {role[:-1]} keys are: {', '.join(sorted(self._keyed[role])) or 'none'}"
            )
        return self._keyed[role][name]

    def _set(self, role: str, topics: Mapping[str, Topic | Sequence[Topic] | None]) -> None:
        if self._node is not None:
            raise RuntimeError(
                f"component {self.component_name!r} is running: change its topics with the change_topic service, not .{role}()"
            )
        allowed = self._allowed(role)
        staged: dict[str, list[Topic]] = {}
        for raw_key, value in topics.items():
            key = self._key(role, raw_key)
            spec = allowed.get(key)
            if spec is None:
                raise UnknownTopicKey(
                    f"component {self.component_name!r} ({type(self).__name__}) has no {role[:-1]} key {key!r}; "
                    f"its {role[:-1]} keys are: {', '.join(sorted(allowed)) or 'none'}"
                )
            staged[key] = check_topics(self.component_name, type(self).__name__, role[:-1], value, spec, key=key)
        replaced = {key: self._keyed[role].get(key, []) for key in staged}
        self._keyed[role].update(staged)
        if role == "inputs" and self._trigger:
            # A trigger that pointed at a replaced topic follows its key to the new topic.
            follow = {old.name: staged[key][0] for key, olds in replaced.items() if staged[key] for old in olds}
            self._trigger = [follow.get(t.name, t) for t in self._trigger]
        self._sync_flat_lists()

    def _sync_flat_lists(self) -> None:
        flat_in = [t for ts in self._keyed["inputs"].values() for t in ts]
        # Triggers that are not keyed inputs stay inputs (BaseComponent adds them to in_topics).
        extra = [t for t in getattr(self, "_trigger", []) if t not in flat_in]
        self.in_topics = _dedupe(flat_in + extra)
        self.out_topics = _dedupe([t for ts in self._keyed["outputs"].values() for t in ts])


def _dedupe(topics: list[Topic]) -> list[Topic]:
    seen: dict[str, Topic] = {}
    for t in topics:
        seen.setdefault(t.name, t)
    return list(seen.values())
