"""The run options of the ROS 2 bridge, as the environment carries them to the run's processes.

``emos run --ros2 [--ros2-topics all|/scan,/cmd_vel] [--ros-domain-id N]`` and a recipe's
``emos.transport.select.use_ros2(...)`` set them; the Launcher adds the bridge when ``$EMOS_ROS2``
is set (through the ``ros2`` entry point of ``emos.frontends``), and the bridge reads them.
"""
from __future__ import annotations

import fnmatch
import os

ENV_ROS2 = "EMOS_ROS2"  # "1": the run bridges to ROS 2
STATE_FILE = "ros2_bridge.json"  # in the run directory: what the bridge carries (emos topic list)
ENV_ROS2_TOPICS = "EMOS_ROS2_TOPICS"  # "all" or names / wildcards separated by ','
ENV_ROS2_DOMAIN = "EMOS_ROS2_DOMAIN_ID"
MAX_DOMAIN_ID = 232  # ROS 2: 0..101 on Linux without port clashes, 215..232 too; rmw refuses more


def parse_topics(value: str | list[str] | None, what: str = "ROS 2 topics") -> list[str]:
    """``[]`` for all, else the names (``scan`` -> ``/scan``) or wildcards; raises naming a bad one."""
    if value is None:
        return []
    if isinstance(value, str):
        parts = [p.strip() for p in value.split(",") if p.strip()]
    elif isinstance(value, (list, tuple)) and all(isinstance(v, str) for v in value):
        parts = [p.strip() for p in value if p.strip()]
    else:
        raise TypeError(f"{what} must be 'all' or a list of topic names, got {value!r}")
    if parts == ["all"]:
        return []
    from emos.io.topic import normalize_topic_name

    out = []
    for part in parts:
        if any(ch in part for ch in "*?["):
            out.append(part if part.startswith("/") else "/" + part)
            fnmatch.translate(part)
            continue
        try:
            out.append(normalize_topic_name(part))
        except ValueError as exc:
            raise ValueError(f"{what}: {exc}") from None
    return out


def check_domain(value: object) -> int | None:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= MAX_DOMAIN_ID:
        raise ValueError(f"ROS 2 domain id must be an int in 0..{MAX_DOMAIN_ID} (as ROS_DOMAIN_ID), got {value!r}")
    return value


def from_environment() -> tuple[bool, list[str], int | None]:
    """``(bridge wanted, topics ([]: all), domain id or None)`` of this run."""
    enabled = os.environ.get(ENV_ROS2, "") == "1"
    topics = parse_topics(os.environ.get(ENV_ROS2_TOPICS) or None, f"${ENV_ROS2_TOPICS}")
    raw = os.environ.get(ENV_ROS2_DOMAIN, "").strip()
    try:
        domain = check_domain(int(raw)) if raw else None
    except ValueError as exc:
        raise ValueError(f"${ENV_ROS2_DOMAIN}: {exc}") from None
    return enabled, topics, domain
