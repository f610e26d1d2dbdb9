"""Where the Monitor reads a component's status from: its own run's rings, or Zenoh.

An event may read ``<name>/status`` of a component of this run (published on a shared-memory
ring, the only place a node publishes it) or of a component of another run, on another host,
whose status that run's Zenoh helper repeats over Zenoh (:mod:`emos.transport.zenoh_status_mirror`).
A status topic's transport therefore follows where the component is, not the run's
``--net-topics`` option:

* a component of this run: shared memory, always (``--net-topics all`` would otherwise send
  the Monitor to Zenoh for a status that is never published there);
* any other component: Zenoh when this run uses it (``--zenoh`` / ``$EMOS_ZENOH_CONFIG``, or the
  topic selected for the network), read TRANSIENT_LOCAL so that the remote component's current
  status arrives as soon as the Monitor starts, not only at its next change.

Every other topic keeps the transport its ``Topic`` and the run give it (see
:mod:`emos.transport.select`): an event on a topic marked for the network reads it over Zenoh.
"""
from __future__ import annotations

import logging
import os
from typing import Collection

import attrs

from emos.config.qos import TRANSIENT_LOCAL
from emos.io.topic import Topic
from emos.msgs.status import ComponentStatus

log = logging.getLogger("emos.monitor")
_STATUS_SUFFIX = "/status"


def status_owner(topic: Topic) -> str | None:
    """The component whose status ``topic`` is (``/<name>/status`` of ``ComponentStatus``), or None."""
    if topic.msg_type is not ComponentStatus or not topic.name.endswith(_STATUS_SUFFIX):
        return None
    owner = topic.name[1 : -len(_STATUS_SUFFIX)]
    return owner or None


def place_inputs(topics: dict[str, Topic], local_components: Collection[str]) -> dict[str, Topic]:
    """``topics`` (name -> Topic) with the transport of each component status topic settled."""
    from emos.transport.select import transport_of
    from emos.transport.zenoh_net import ENV_ZENOH_CONFIG

    local = {name.strip("/") for name in local_components}
    uses_zenoh = bool(os.environ.get(ENV_ZENOH_CONFIG))
    placed: dict[str, Topic] = {}
    for name, topic in topics.items():
        owner = status_owner(topic)
        if owner is None:
            placed[name] = topic
        elif owner in local:
            placed[name] = topic if topic.transport == "shm" else attrs.evolve(topic, transport="shm")
        elif topic.transport == "shm":
            log.warning("events read %s of %r, which is not a component of this run, from shared memory as the topic says: "
                        "only a component of this run could publish it there", name, owner)
            placed[name] = topic
        elif uses_zenoh or transport_of(name, topic.transport) == "zenoh":
            qos = attrs.evolve(topic.qos_profile, durability=TRANSIENT_LOCAL)
            placed[name] = attrs.evolve(topic, transport="zenoh", qos_profile=qos)
        else:
            log.warning("events read %s, but %r is not a component of this run and the run does not use Zenoh "
                        "(emos run --zenoh CONFIG): its status will never arrive", name, owner)
            placed[name] = topic
    return placed
