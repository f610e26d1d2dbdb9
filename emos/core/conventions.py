"""What every component convention shares: declared topic types and the config class.

EMOS has two ways for a component to declare its topics, both built on what is here:

- *keyed* (:class:`emos.core.keyed.KeyedComponent`: the navigation components, the simulator):
  one :class:`AllowedTopic` per role key (``"map"``, ``"goal_point"``), each with its types, a
  count, a default and whether it is required;
- *listed* (``emos.actors.agents.components.ModelComponent``: LLM, Vision, ...): the recipe gives
  plain ``inputs=[...]`` / ``outputs=[...]`` lists and the class declares the types every input
  (or output) may carry; that is one :class:`AllowedTopic` per role with no key and any count
  (:func:`role_spec`).

Either way a topic is checked once, here (:func:`check_topics`), at definition time: it must be a
:class:`~emos.io.topic.Topic`, of a type the role accepts (a subclass of an accepted type counts),
no more of them than the role takes, and present when the role is required. The error names the
component, the role (and its key) and the accepted types.

The config object follows one rule too (:func:`resolve_config`): a component class names its
config class (``BaseComponent.config_class()``); a recipe that passes none gets a default
instance, and one of another class fails naming both classes.
"""
from __future__ import annotations

import functools
from collections.abc import Iterable, Sequence
from typing import Any, TypeVar

from attrs import define, field

from emos.io.topic import Topic
from emos.msgs.registry import canonical_name, resolve

__all__ = ["AllowedTopic", "check_topics", "resolve_config", "role_spec"]

C = TypeVar("C")


def _type_names(value: Sequence[Any]) -> tuple[str, ...]:
    if isinstance(value, (str, type)):
        value = (value,)
    names = tuple(canonical_name(resolve(v)) for v in value)  # unknown names fail at class definition
    if not names:
        raise ValueError("AllowedTopic.types must name at least one message type")
    return names


@define(frozen=True)
class AllowedTopic:
    """What one role accepts: message types, how many topics (``number``; ``-1`` = any), a default.

    ``required``: the component cannot run without a topic for this key (bringup fails with the
    key named); a key with no default and ``required=False`` is an optional feature the recipe
    switches on by giving a topic (e.g. the controller's ``vision_tracking``).
    """

    types: tuple[str, ...] = field(converter=_type_names)
    default: Topic | list[Topic] | None = None
    number: int = 1
    required: bool = False

    def __attrs_post_init__(self) -> None:
        if self.number == 0 or self.number < -1:
            raise ValueError(f"AllowedTopic.number must be >= 1 or -1 (any), got {self.number}")

    @property
    def classes(self) -> tuple[type, ...]:
        """The accepted message classes (resolved once per set of names)."""
        return _classes(self.types)

    def accepts(self, topic: Topic) -> bool:
        return issubclass(topic.msg_type, self.classes)


@functools.cache
def _classes(names: tuple[str, ...]) -> tuple[type, ...]:
    return tuple(resolve(n) for n in names)


def short_type(type_name: str) -> str:
    """``sensor_msgs/msg/Image`` -> ``Image`` (how error messages name a type)."""
    return type_name.rsplit("/", 1)[-1]


def role_spec(types: Sequence[type | str]) -> AllowedTopic | None:
    """The declaration of a listed role (every input, or every output): the given types, any
    number of topics. No types means the role takes any message type (None)."""
    return _role_spec(tuple(types))


@functools.cache
def _role_spec(types: tuple[type | str, ...]) -> AllowedTopic | None:
    return AllowedTopic(types=types, number=-1) if types else None


def check_topics(
    component: str,
    component_type: str,
    role: str,
    given: Topic | Iterable[object] | None,
    spec: AllowedTopic | None,
    key: str | None = None,
) -> list[Topic]:
    """Check the topics a recipe gives one role and return them as a list.

    ``role`` is ``"input"`` or ``"output"``; ``key`` names the role's key on a keyed component and
    is None for a listed role (the messages then name the topic instead of a key). ``spec`` None
    accepts any type and any number."""
    # What recipes give is checked, not trusted: any object may be in the list.
    items: list[object] = [] if given is None else ([given] if isinstance(given, Topic) else list(given))
    topics: list[Topic] = []
    for t in items:
        if not isinstance(t, Topic):
            if key is None:
                raise TypeError(f"component {component!r}: {role}s must be Topic objects, got {type(t).__name__} {t!r}")
            raise TypeError(f"component {component!r}: {role} {key!r} must be a Topic, got {type(t).__name__} {t!r}")
        if spec is not None and not spec.accepts(t):
            if key is None:
                raise TypeError(
                    f"component {component!r} ({component_type}): {role} {t.name!r} carries {t.type_name}, but this "
                    f"component takes {role}s of type {', '.join(short_type(n) for n in spec.types)}"
                )
            raise TypeError(
                f"component {component!r} ({component_type}): {role} {key!r} accepts "
                f"{' or '.join(short_type(n) for n in spec.types)}, but topic {t.name!r} is {short_type(t.type_name)}"
            )
        topics.append(t)
    if spec is None:
        return topics
    label = f"{role} {key!r}" if key is not None else f"{role}s"
    if spec.number != -1 and len(topics) > spec.number:
        raise ValueError(f"component {component!r}: {label} takes at most {spec.number} topic(s), got {len(topics)}")
    if not topics and spec.required:
        raise ValueError(f"component {component!r}: {label} is required and cannot be removed")
    return topics


def resolve_config(component: str, component_type: str, config: object, config_cls: type[C]) -> C:
    """The config a component runs with: ``config`` if it is a ``config_cls``, a default
    ``config_cls()`` if None; anything else fails naming the expected class."""
    if config is None:
        return config_cls()
    if not isinstance(config, config_cls):
        raise TypeError(f"component {component!r} ({component_type}): config must be a {config_cls.__name__}, "
                        f"got {type(config).__name__}")
    return config
