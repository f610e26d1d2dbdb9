"""Where the Monitor reads a component's status from, and where its actions on a component go:
its own run (rings, control sockets, the supervisor), or another run of the group over Zenoh.

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

Actions follow the same rule (:class:`ActionRoutes`): one on a component of this run goes to its
control socket or to the supervisor as always; one on any other component (named in the recipe
by a component object of that name which this run does not launch) goes over Zenoh to the run
that has it (:mod:`emos.transport.zenoh_control`), when this run uses Zenoh.
"""
from __future__ import annotations

import asyncio
import concurrent.futures
import logging
import os
from collections.abc import Collection
from typing import Any

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
    from emos.transport.zenoh_config import ENV_ZENOH_CONFIG

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


def uses_zenoh() -> bool:
    from emos.transport.zenoh_config import ENV_ZENOH_CONFIG

    return bool(os.environ.get(ENV_ZENOH_CONFIG))


class ActionRoutes:
    """Sends the Monitor's actions on components of other runs over Zenoh."""

    def __init__(self, local_components: Collection[str], timeout: float):
        self.local = {name.strip("/") for name in local_components}
        self.timeout = timeout
        self._remote: Any = None
        # Its own threads: a remote restart may take seconds, and must not hold the threads that
        # run the recipe's functions.
        self._pool: concurrent.futures.ThreadPoolExecutor | None = None

    def is_remote(self, component: str) -> bool:
        return component not in self.local

    async def request(self, component: str, req: dict, timeout: float | None = None) -> Any:
        from emos.events.action import ActionError
        from emos.transport.zenoh_control import RemoteControl

        if not uses_zenoh():
            raise ActionError(f"component {component!r} is not in this run, and this run does not use Zenoh (emos run --zenoh CONFIG): "
                              f"{req.get('op')} not delivered")
        if self._remote is None:
            self._remote = RemoteControl()
        if self._pool is None:
            self._pool = concurrent.futures.ThreadPoolExecutor(max_workers=4, thread_name_prefix="emos-remote-action")
        loop = asyncio.get_running_loop()
        return await loop.run_in_executor(self._pool, self._remote.request, component, req, self.timeout if timeout is None else timeout)

    async def control(self, component: str, call: str, args: dict, timeout: float) -> Any:
        return await self.request(component, {"op": "control", "call": call, "args": args}, timeout)

    async def lifecycle(self, component: str, op: str, wait_time: float) -> Any:
        return await self.request(component, {"op": "lifecycle", "request": op, "wait_time": float(wait_time)})

    async def call_service(self, component: str, name: str, request: Any, response_type: type) -> Any:
        from emos.msgs import codec

        raw = await self.request(component, {"op": "service", "name": name, "request": codec.pack(request)})
        return codec.decode(response_type, raw, copy=True)

    async def send_goal(self, component: str, name: str, goal: Any) -> Any:
        from emos.msgs import codec

        return await self.request(component, {"op": "goal", "name": name, "goal": codec.pack(goal)})

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool = None
