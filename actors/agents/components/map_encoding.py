"""``MapEncoding``: a spatio-temporal semantic map in a vector DB.

Each trigger (timed, 15 s in the recipe) stores the newest message of every ``MapLayer`` at
the robot's current position (from ``position``), binned on the occupancy grid of
``map_topic`` (its resolution times the layer's ``resolution_multiple``). Layers without
``temporal_change`` keep one entry per cell; with it, every observation. A store that cannot
be opened (a read-only or corrupt Chroma directory) is a COMPONENT_FAILURE that the component
reports and retries, never a crash.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any, ClassVar

from attrs import define, field

from emos.config import validators as V
from emos.core import clock
from emos.io.topic import Topic
from emos.msgs import geometry as G
from emos.msgs import nav as N

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
        self._stored: dict[str, int] = {}  # layer -> id() of the last message stored
        self._pre_defined_done = False
        self.entries_written = 0

    def activate_resources(self) -> None:
        super().activate_resources()
        self._encoder.config = MapSettings(map_name=self.config.map_name, distance_func=self.config.distance_func)
        self._stored.clear()
        self._pre_defined_done = False

    def _execution_step(self, msg: Any = None, topic: Topic | None = None, **kwargs: Any) -> None:
        if self._worker is not None and self._worker.busy:
            return  # the previous write is still going: this trigger's data is stored next time
        super()._execution_step(msg, topic)

    def missing_inputs(self, inputs: Mapping[str, Any]) -> list[str]:
        return [t.name for t in (self.position, self.map_topic) if t.name not in inputs]

    def prepare(self, inputs: dict[str, Any], trigger: Topic | None) -> Callable[[], None] | None:
        grid = inputs[self.map_topic.name]
        resolution = float(grid.info.resolution)
        position = position_of(inputs[self.position.name])
        observations = []
        for layer in self.layers:
            msg = inputs.get(layer.name)
            if msg is None or self._stored.get(layer.name) == id(msg):
                continue
            observations.append((layer.name, text_of(msg), id(msg)))
        at = clock.now()  # observed now on the node's clock (simulated seconds under a simulator)
        return lambda: self._write(resolution, position, observations, at)

    def _write(self, resolution: float, position: Any, observations: list[tuple[str, str, int]],
               at: float | None = None) -> None:
        if not resolution > 0:
            self.health_status.set_fail_system(topic_names=[self.map_topic.name],
                                               message=f"{self.map_topic.name}: map resolution {resolution} is not > 0")
            return
        try:
            self._encoder.set_resolution(resolution)
            if not self._pre_defined_done:
                self.entries_written += len(self._encoder.add_pre_defined(timestamp=at))
                self._pre_defined_done = True
            for layer, text, ident in observations:
                self.entries_written += len(self._encoder.encode(layer, text, position, timestamp=at) and [1] or [])
                self._stored[layer] = ident
        except Exception as exc:  # the store refused the write (read-only, corrupt, full disk)
            self.health_status.set_fail_component(component_names=[self.component_name],
                                                  message=f"map store {self.config.map_name!r}: {type(exc).__name__}: {exc}")
            self._errors("write", "[%s] cannot write to the map store: %s", self.component_name, exc)
            return
        self.health_status.set_healthy()
