"""Feeding and reading topics of a recipe running under ``emos run`` (agent component tests)."""
from __future__ import annotations

import time
from typing import Any

from emos.msgs.registry import resolve
from emos.transport.pubsub import Publisher, Subscriber
from tests.runtime.helpers import SystemUnderTest, wait_until

AGENT_HEADER = """
from emos import FixedInput
from emos.actors.agents import OllamaClient, OllamaModel, GenericHTTPClient, GenericLLM, GenericMLLM
from emos.actors.agents import LLM, LLMConfig, MLLM, VLM, VLMConfig
"""


class Probe:
    """Publishers and subscribers on a running system's topics, closed together."""

    def __init__(self, system: SystemUnderTest) -> None:
        self.system = system
        self.pubs: dict[str, Publisher] = {}
        self.subs: dict[str, Subscriber] = {}

    def pub(self, topic: str, msg: Any) -> None:
        if topic not in self.pubs:
            self.pubs[topic] = Publisher(self.system.ctx, topic, type(msg), publisher_id="probe", depth=8)
        self.pubs[topic].publish(msg)

    def sub(self, topic: str, msg_type: str) -> Subscriber:
        if topic not in self.subs:
            self.subs[topic] = Subscriber(self.system.ctx, topic, resolve(msg_type), queue_size=100)
        return self.subs[topic]

    def collect(self, topic: str, msg_type: str, count: int = 1, timeout: float = 30.0) -> list[Any]:
        sub = self.sub(topic, msg_type)
        got: list[Any] = []

        def enough() -> bool:
            got.extend(sub.take())
            return len(got) >= count

        wait_until(enough, timeout, what=f"{count} message(s) on {topic}")
        return got

    def drain(self, topic: str, msg_type: str, settle: float = 0.5) -> list[Any]:
        sub = self.sub(topic, msg_type)
        time.sleep(settle)
        return sub.take()

    def status(self, component: str) -> Any:
        sub = self.sub(f"/{component}/status", "ComponentStatus")
        return wait_until(sub.latest, 20, what=f"a status of {component}")

    def close(self) -> None:
        for p in self.pubs.values():
            p.close()
        for s in self.subs.values():
            s.close()


def sim_status(system: SystemUnderTest, component: str = "sim") -> dict:
    """The running Simulator's ``sim_status`` (commands received, collisions, movers' poses)."""
    from emos.core.node import control_socket
    from emos.core.rpc import RpcClient

    client = RpcClient(control_socket(system.ctx, component))
    try:
        return client.call("execute_method", method="sim_status", timeout=10.0)
    finally:
        client.close()
