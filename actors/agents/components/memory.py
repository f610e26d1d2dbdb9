"""``Memory``: the robot's spatio-temporal memory as a component (EmbodiedAgents' eMEM).

    memory = Memory(position=odom, inputs=[detections, captions, battery, planner.status_topic],
                    db_client=chroma, model_client=llm_client, component_name="memory")

Every step (``loop_rate``, default 1 Hz) it records what is new on its inputs at the robot's
current position: detections (their labels), text (captions, what was said: any String), the
battery (``BatteryState`` or a ``Float32`` fraction) and the health of the components whose
``ComponentStatus`` topics it reads (faults and recoveries). The index is a
:class:`~..memory.store.MemoryStore`: by place, time, label, and meaning through the Chroma
``db_client`` (embedded with the client's model, all-MiniLM-L6-v2 by default). With a
``model_client``, episodes (consolidated old records, and ``episode_summary``) are summarised
by the model; without one, by counting what was seen.

The tools (``semantic_search``, ``spatial_query``, ``temporal_query``, ``episode_summary``,
``locate``, ``recall``, ``body_status``) are public methods: recipes call them as actions
(``Action(memory.locate, kwargs=...)``), and Cortex finds them as tools of any component of type
Memory. A query with an impossible range raises :class:`MemoryQueryError` with the reason, which
the caller (an action, Cortex's step) reports.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any, ClassVar

from attrs import define, field

from emos.config import validators as V
from emos.io.topic import Topic
from emos.msgs import geometry as G
from emos.msgs import intelligence as I
from emos.msgs import nav as N
from emos.msgs import sensor as S
from emos.msgs import status as ST
from emos.msgs import std as D

from ..memory.store import MemoryQueryError, MemoryRecord, MemoryStore, default_summary
from ..types import ChatMessage, ChatRequest
from .base import ModelComponent, ModelComponentConfig
from .convert import position_of, text_of

__all__ = ["Memory", "MemoryConfig", "MemoryQueryError"]

POSITION_TYPES = (N.Odometry, G.PoseStamped, G.Pose, G.Point, G.PointStamped)
_LEVELS = {ST.ComponentStatus.STATUS_FAILURE_ALGORITHM_LEVEL: "algorithm failure",
           ST.ComponentStatus.STATUS_FAILURE_COMPONENT_LEVEL: "component failure",
           ST.ComponentStatus.STATUS_FAILURE_SYSTEM_LEVEL: "system failure"}


@define(kw_only=True)
class MemoryConfig(ModelComponentConfig):
    max_records: int = field(default=5000, validator=V.in_range(8, 10_000_000))
    """Raw records kept before the oldest quarter is consolidated into episodes."""
    episode_s: float = field(default=60.0, validator=V.in_range(1.0, 86_400.0))
    """Length of one episode window (s) when records are consolidated."""
    collection_name: str = field(default="emos_memory")
    summary_max_tokens: int = field(default=120, validator=V.in_range(8, 10_000))


class Memory(ModelComponent):
    CONFIG_CLASS: ClassVar[type] = MemoryConfig
    ALLOWED_INPUTS: ClassVar[tuple[type, ...]] = (I.Detections, I.Trackings, D.String, I.StreamingString, S.BatteryState,
                                                  D.Float32, D.Float64, ST.ComponentStatus) + POSITION_TYPES
    ALLOWED_OUTPUTS: ClassVar[tuple[type, ...]] = ()
    MODEL_OPTIONAL: ClassVar[bool] = True

    def __init__(self, *, position: Topic, inputs: Sequence[Topic] | None = None, db_client: Any = None,
                 model_client: Any = None, config: MemoryConfig | None = None, trigger: Any = 1.0,
                 component_name: str, **kwargs: Any) -> None:
        if not isinstance(position, Topic) or not issubclass(position.msg_type, POSITION_TYPES):
            raise TypeError(f"component {component_name!r}: position must be a Topic of Odometry, PoseStamped, Pose, "
                            f"Point or PointStamped, got {position!r}")
        super().__init__(inputs=[position, *(inputs or [])], model_client=model_client, db_client=db_client,
                         config=config, trigger=trigger, component_name=component_name, **kwargs)
        self.config: MemoryConfig
        self.position_topic = position
        self.store: MemoryStore | None = None
        self._seen: dict[str, Any] = {}  # topic -> the last message recorded

    # ------------------------------------------------------------------ resources
    def activate_resources(self) -> None:
        super().activate_resources()  # opens the Chroma client
        summarize = self._model_summary if self.model_client is not None else None
        self.store = MemoryStore(max_records=self.config.max_records, episode_s=self.config.episode_s,
                                 vector=self.db_client, collection=self.config.collection_name, summarize=summarize)

    def _model_summary(self, records: Sequence[MemoryRecord]) -> str:
        lines = "\n".join(f"- {r.text}" + (f" at ({r.x:.1f}, {r.y:.1f})" if math.isfinite(r.x) else "") for r in records[:60])
        request = ChatRequest(messages=[ChatMessage(role="system", content="Summarise what a robot observed in one or two sentences."),
                                        ChatMessage(role="user", content=f"Observations:\n{lines}\nSummary:")],
                              temperature=0.0, max_tokens=self.config.summary_max_tokens)
        text = (self.call_model(lambda client: client.chat(request)).message.content or "").strip()
        return text or default_summary(records)

    # ------------------------------------------------------------------ steps
    def _fresh(self, inputs: Mapping[str, Any], topic: Topic) -> Any:
        msg = inputs.get(topic.name)
        if msg is None or self._seen.get(topic.name) is msg:
            return None
        # The message itself is kept (not its id: a freed message's id is reused by the next one).
        self._seen[topic.name] = msg
        return msg

    def prepare(self, inputs: dict[str, Any], trigger: Topic | None) -> Callable[[], None] | None:
        pos = inputs.get(self.position_topic.name)
        xy = None
        if pos is not None:
            p = position_of(pos)
            xy = (float(p[0]), float(p[1])) if math.isfinite(p[0]) and math.isfinite(p[1]) else None
        work: list[tuple[str, Any]] = []
        for topic in self.input_topics:
            if topic.name == self.position_topic.name:
                continue
            msg = self._fresh(inputs, topic)
            if msg is not None:
                work.append((topic.name, msg))
        return lambda: self._record(xy, work)

    def _record(self, xy: tuple[float, float] | None, work: list[tuple[str, Any]]) -> None:
        store = self.store
        if store is None:
            return
        if xy is not None:
            store.update_body(x=xy[0], y=xy[1])
        faults = dict(store.body["faults"])
        changed = False
        for name, msg in work:
            if isinstance(msg, (I.Detections, I.Trackings)):
                store.observe_detections(list(msg.labels))
            elif isinstance(msg, S.BatteryState):
                store.update_body(battery=float(msg.percentage))
            elif isinstance(msg, (D.Float32, D.Float64)):
                store.update_body(battery=float(msg.data))
            elif isinstance(msg, ST.ComponentStatus):
                component = name.strip("/").rsplit("/status", 1)[0]
                level = _LEVELS.get(msg.status)
                if level is None:
                    changed |= faults.pop(component, None) is not None
                elif faults.get(component) != level:
                    faults[component], changed = f"{level}{': ' + msg.message if msg.message else ''}"[:200], True
            else:
                text = text_of(msg).strip()
                if text:
                    store.add("caption", f"{name.strip('/')}: {text}")
        if changed:
            store.update_body(faults=faults)
        self.health_status.set_healthy()

    # ------------------------------------------------------------------ the tools (also actions)
    def _store(self) -> MemoryStore:
        if self.store is None:
            raise RuntimeError(f"component {self.component_name!r}: the memory is not open yet (the component is not active)")
        return self.store

    def semantic_search(self, query: str, n_results: int = 3) -> list[dict]:
        return self._store().semantic_search(query, n_results)

    def spatial_query(self, x: float, y: float, radius: float, n_results: int = 20) -> list[dict]:
        return self._store().spatial_query(x, y, radius, n_results)

    def temporal_query(self, since_s: float, until_s: float = 0.0, n_results: int = 50) -> list[dict]:
        return self._store().temporal_query(since_s, until_s, n_results)

    def episode_summary(self, since_s: float) -> str:
        return self._store().episode_summary(since_s)

    def locate(self, label: str) -> dict:
        return self._store().locate(label)

    def recall(self, subject: str) -> dict:
        return self._store().recall(subject)

    def body_status(self) -> dict:
        return self._store().body_status()

    def remember(self, text: str, kind: str = "event") -> bool:
        """Add a note (an event a recipe or Cortex wants kept); returns True."""
        self._store().add(kind, text)
        return True
