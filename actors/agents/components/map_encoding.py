"""``MapEncoding``: a spatio-temporal semantic map in a vector DB.

Each trigger (timed, 15 s in the recipe) stores the newest message of every ``MapLayer`` at
the robot's current position (from ``position``), binned on the occupancy grid of
``map_topic`` (its resolution times the layer's ``resolution_multiple``). Layers without
``temporal_change`` keep one entry per cell; with it, every observation. A store that cannot
be opened (a read-only or corrupt Chroma directory) is a COMPONENT_FAILURE that the component
reports and retries, never a crash.

The DB client (and its embedding model) is opened at activation, in the model worker, not by the
first write: loading the model took 17-85 s on a loaded machine, and a first write that paid for
it blocked the map for 85 s (one entry in 100 s). While it loads, the status is GENERAL with a
message that says so. Each trigger's observations are taken on the event loop and queued for the
worker in order: a write that takes longer than the trigger period delays the next one, it does
not skip it. Observations that are not stored (the queue overflowed, the store cannot be opened)
are logged, rate-limited, with a count naming the component and the layers' topics.
"""
from __future__ import annotations

import collections
import threading
from collections.abc import Callable, Mapping, Sequence
from typing import Any, ClassVar

from attrs import define, field

from emos.config import validators as V
from emos.core import clock
from emos.core.health import HealthLevel
from emos.io.topic import Topic
from emos.msgs import geometry as G
from emos.msgs import nav as N
from emos.ratelimit import RateLimitedLog

from ..db.spec import DISTANCES
from ..logic.map_encoding import MapConfig as MapSettings
from ..logic.map_encoding import MapEncoder, MapLayer
from .base import ModelComponent, ModelComponentConfig
from .convert import TEXTUAL_TYPES, position_of, text_of

__all__ = ["MapEncoding", "MapConfig", "MapLayer"]


def _map_name(instance: Any, attribute: Any, value: Any) -> None:
    if not isinstance(value, str) or len(value) < 3:
        raise ValueError(f"MapConfig.map_name: expected a collection name of 3+ characters, got {value!r}")


@define(kw_only=True)
class MapConfig(ModelComponentConfig):
    map_name: str = field(default="map", validator=_map_name)
    distance_func: str = field(default="l2", validator=V.in_(DISTANCES))


POSITION_TYPES = (N.Odometry, G.PoseStamped, G.Pose, G.Point, G.PointStamped)

#: (layer name, text, the message) of one observation taken at a trigger
Observation = tuple[str, str, Any]


@define(frozen=True)
class _Trigger:
    """What one trigger observed, taken on the event loop, written later by the worker."""

    resolution: float
    position: Any
    observations: list[Observation]
    at: float | None


class MapEncoding(ModelComponent):
    CONFIG_CLASS: ClassVar[type] = MapConfig
    ALLOWED_INPUTS: ClassVar[tuple[type, ...]] = TEXTUAL_TYPES + POSITION_TYPES + (N.OccupancyGrid,)
    MODEL_OPTIONAL: ClassVar[bool] = True

    def __init__(self, *, layers: Sequence[MapLayer], position: Topic, map_topic: Topic, db_client: Any,
                 config: MapConfig | None = None, trigger: Any = 10.0, component_name: str, **kwargs: Any) -> None:
        layers = list(layers)
        if not layers or not all(isinstance(layer, MapLayer) for layer in layers):
            raise ValueError(f"component {component_name!r}: layers must be a non-empty list of MapLayer")
        for layer in layers:
            if not isinstance(layer.subscribes_to, Topic) or not issubclass(layer.subscribes_to.msg_type, TEXTUAL_TYPES):
                raise TypeError(f"component {component_name!r}: MapLayer {layer.name!r} must subscribe to a String, "
                                "StreamingString, Detections or Trackings Topic")
        if not isinstance(position, Topic) or not issubclass(position.msg_type, POSITION_TYPES):
            raise TypeError(f"component {component_name!r}: position must be an Odometry, PoseStamped or Point Topic")
        if not isinstance(map_topic, Topic) or map_topic.msg_type is not N.OccupancyGrid:
            raise TypeError(f"component {component_name!r}: map_topic must be an OccupancyGrid Topic")
        if db_client is None:
            raise ValueError(f"component {component_name!r}: MapEncoding needs a db_client")
        super().__init__(inputs=[layer.subscribes_to for layer in layers] + [position, map_topic], outputs=[],
                         config=config, db_client=db_client, trigger=trigger, component_name=component_name, **kwargs)
        self.config: MapConfig
        self.layers = layers
        self.position = position
        self.map_topic = map_topic
        self._encoder = MapEncoder(layers, db_client, MapSettings(map_name=self.config.map_name,
                                                                  distance_func=self.config.distance_func))
        # layer -> the last message taken for a write (on the loop, when the trigger is queued,
        # so two queued triggers never take one message twice; given back when the write fails,
        # so that the next trigger takes it again). The message itself, not its id(): a new
        # message can get the id() of a freed one and be taken for stored already (the likely
        # reason one trigger of six wrote nothing in a measured 100 s run of the recipe).
        self._stored: dict[str, Any] = {}
        self._stored_lock = threading.Lock()
        # Triggers waiting for the worker, oldest first, at most max_pending (older ones are
        # dropped, and said so). Every trigger also queues a flush job that writes all of them:
        # a flush job the worker drops from its own queue loses nothing.
        self._backlog: collections.deque[_Trigger] = collections.deque()
        self._backlog_lock = threading.Lock()
        self._pre_defined_done = False
        self.entries_written = 0
        self.dropped_observations = 0  # observations not stored (each one logged, rate-limited)
        self._drops = RateLimitedLog(self.get_logger(), interval=5.0)

    def activate_resources(self) -> None:
        loading = f"{self.component_name}: opening the map store {self.config.map_name!r} and loading its embedding model"
        self.health_status.set_general(loading)
        self._publish_status()
        super().activate_resources()  # opens the DB client, which loads its embedding model
        self._encoder.config = MapSettings(map_name=self.config.map_name, distance_func=self.config.distance_func)
        self._pre_defined_done = False
        if self.health_status.level == HealthLevel.GENERAL and self.health_status.message == loading:
            # Ready; a newer report (inputs missing, said by a step meanwhile) stays.
            self.health_status.set_healthy()
            self._publish_status()

    def custom_on_deactivate(self) -> None:
        super().custom_on_deactivate()
        with self._backlog_lock:
            left = list(self._backlog)
            self._backlog.clear()
        for trig in left:
            self._dropped(trig.observations, "the component was deactivated before they were written")
        with self._stored_lock:
            self._stored.clear()

    # ------------------------------------------------------------------ observations not stored
    def _dropped(self, observations: list[Observation], why: str) -> None:
        if not observations:
            return
        self.dropped_observations += len(observations)
        with self._stored_lock:
            for layer, _, msg in observations:
                if self._stored.get(layer) is msg:
                    del self._stored[layer]  # not stored: the next trigger takes it again
        topics = ", ".join(sorted({layer for layer, _, _ in observations}))
        self._drops.warning(("drop", why), "[%s] %d observation(s) of %s not stored in map %r: %s (%d in all)",
                            self.component_name, len(observations), topics, self.config.map_name, why,
                            self.dropped_observations)

    def _run_job(self, job: Callable[[], None]) -> None:
        if not self.ensure_resources():
            with self._backlog_lock:
                left = list(self._backlog)
                self._backlog.clear()
            for trig in left:
                self._dropped(trig.observations, "the map store cannot be opened; the status says why")
            self._publish_status()
            return
        super()._run_job(job)

    # ------------------------------------------------------------------ steps
    def missing_inputs(self, inputs: Mapping[str, Any]) -> list[str]:
        return [t.name for t in (self.position, self.map_topic) if t.name not in inputs]

    def prepare(self, inputs: dict[str, Any], trigger: Topic | None) -> Callable[[], None] | None:
        grid = inputs[self.map_topic.name]
        resolution = float(grid.info.resolution)
        position = position_of(inputs[self.position.name])
        observations: list[Observation] = []
        with self._stored_lock:
            for layer in self.layers:
                msg = inputs.get(layer.name)
                if msg is None or self._stored.get(layer.name) is msg:
                    continue
                observations.append((layer.name, text_of(msg), msg))
                self._stored[layer.name] = msg
        at = clock.now()  # observed now on the node's clock (simulated seconds under a simulator)
        overflow: list[_Trigger] = []
        with self._backlog_lock:
            self._backlog.append(_Trigger(resolution, position, observations, at))
            while len(self._backlog) > self.config.max_pending:
                overflow.append(self._backlog.popleft())
        for trig in overflow:
            self._dropped(trig.observations, f"more than max_pending={self.config.max_pending} triggers waiting for "
                                             "the store; the oldest was dropped")
        return self._flush

    def _flush(self) -> None:
        """Worker: write every waiting trigger, oldest first."""
        while True:
            with self._backlog_lock:
                if not self._backlog:
                    return
                trig = self._backlog.popleft()
            self._write(trig.resolution, trig.position, trig.observations, trig.at)

    def _write(self, resolution: float, position: Any, observations: list[Observation],
               at: float | None = None) -> None:
        if not resolution > 0:
            self.health_status.set_fail_system(topic_names=[self.map_topic.name],
                                               message=f"{self.map_topic.name}: map resolution {resolution} is not > 0")
            self._dropped(observations, f"map resolution {resolution} on {self.map_topic.name} is not > 0")
            return
        done = 0
        try:
            self._encoder.set_resolution(resolution)
            if not self._pre_defined_done:
                self.entries_written += len(self._encoder.add_pre_defined(timestamp=at))
                self._pre_defined_done = True
            for layer, text, _ in observations:
                self.entries_written += 1 if self._encoder.encode(layer, text, position, timestamp=at) else 0
                done += 1
        except Exception as exc:  # the store refused the write (read-only, corrupt, full disk)
            self.health_status.set_fail_component(component_names=[self.component_name],
                                                  message=f"map store {self.config.map_name!r}: {type(exc).__name__}: {exc}")
            self._errors("write", "[%s] cannot write to the map store: %s", self.component_name, exc)
            self._dropped(observations[done:], f"the store refused the write ({type(exc).__name__})")
            return
        self.health_status.set_healthy()
