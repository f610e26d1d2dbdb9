"""Checks over a whole system's components, run at bring-up before any process starts."""
from __future__ import annotations

import logging
from collections.abc import Iterable

from emos.config.base import ComponentRunType
from emos.config.loader import ConfigError, read_config_file, section_problems
from emos.core.component import BaseComponent
from emos.errors import EmosError
from emos.msgs.registry import canonical_name
from emos.transport.limits import check_socket_name

log = logging.getLogger("emos.config")


class TopicTypeConflict(EmosError, TypeError):
    """Two components declare one topic with different message types."""


def check_topic_types(components: Iterable[BaseComponent]) -> None:
    """Every topic has one message type across the system (inputs, outputs and status topics).

    A ring carries one type; a second type on the same name would fail in every subscriber at
    run time, once per rescan, so it is refused here, naming both sides.
    """
    seen: dict[str, tuple[type, str]] = {}
    for comp in components:
        declared = [(t, "input") for t in comp.in_topics] + [(t, "output") for t in comp.out_topics] + [(comp.status_topic, "status")]
        for topic, role in declared:
            first = seen.get(topic.name)
            where = f"component {comp.component_name!r} ({role})"
            if first is None:
                seen[topic.name] = (topic.msg_type, where)
            elif first[0] is not topic.msg_type:
                raise TopicTypeConflict(
                    f"topic {topic.name!r} is declared as {canonical_name(first[0])} by {first[1]} "
                    f"and as {canonical_name(topic.msg_type)} by {where}; a topic carries one message type"
                )


def check_server_names(components: Iterable[BaseComponent]) -> None:
    """Service and action names of Server / ActionServer components fit their socket paths."""
    for comp in components:
        if comp.run_type == ComponentRunType.SERVER:
            check_socket_name(f"component {comp.component_name!r}: service", comp.main_srv_name)
        elif comp.run_type == ComponentRunType.ACTION_SERVER:
            check_socket_name(f"component {comp.component_name!r}: action", comp.main_action_name)


def warn_unused_config_sections(components: Iterable[BaseComponent]) -> list[str]:
    """Log (and return) the sections of the components' config files that nothing reads."""
    components = list(components)
    names = [c.component_name for c in components]
    problems: list[str] = []
    for path in sorted({str(c.config_file) for c in components if c.config_file}):
        try:
            data = read_config_file(path)
        except ConfigError:
            continue  # already reported when the component loaded it
        problems.extend(section_problems(data, names, path))
    for problem in problems:
        log.warning("%s", problem)
    return problems


def check_system(components: Iterable[BaseComponent]) -> None:
    components = list(components)
    check_topic_types(components)
    check_server_names(components)
    warn_unused_config_sections(components)
