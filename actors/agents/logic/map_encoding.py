"""MapEncoding storage: semantic outputs stored in a vector DB at binned map coordinates.

Positions (x, y) are binned on a grid of ``map resolution * resolution_multiple`` metres. A layer
without ``temporal_change`` keeps one entry per cell (a new observation overwrites the old);
a layer with it keeps every observation, its id carrying the timestamp. Each entry's metadata
holds ``coordinates`` ([x, y, z], x and y at the cell centre), ``layer_name``, ``timestamp`` and
``temporal_change``, which is what RAG with ``add_metadata=True`` hands to the model.
"""
from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import attrs
import numpy as np

from emos.config import validators as V

from ..db.spec import DISTANCES


def _position(value: Any) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64).reshape(-1)
    if arr.size == 2:
        arr = np.append(arr, 0.0)  # planar robots: z = 0
    if arr.size != 3 or not np.all(np.isfinite(arr)):
        raise ValueError(f"position: expected finite [x, y] or [x, y, z], got {value!r}")
    return arr


def _pre_defined(value: Sequence[tuple[Any, str]]) -> list[tuple[np.ndarray, str]]:
    out = []
    for i, item in enumerate(value or []):
        try:
            position, text = item
        except (TypeError, ValueError):
            raise ValueError(f"pre_defined[{i}]: expected a (position, text) pair, got {item!r}") from None
        if not isinstance(text, str) or not text.strip():
            raise ValueError(f"pre_defined[{i}]: expected a non-empty text, got {text!r}")
        out.append((_position(position), text))
    return out


def _layer_name(value: Any) -> str:
    name = value if isinstance(value, str) else getattr(value, "name", None)
    if not isinstance(name, str) or not name:
        raise TypeError(f"MapLayer.subscribes_to: expected a Topic or topic name, got {type(value).__name__}")
    return name


@attrs.define(kw_only=True)
class MapLayer:
    subscribes_to: Any = attrs.field()
    temporal_change: bool = attrs.field(default=False, validator=attrs.validators.instance_of(bool))
    resolution_multiple: int = attrs.field(default=1, validator=V.int_at_least(1))
    pre_defined: list[tuple[np.ndarray, str]] = attrs.field(factory=list, converter=_pre_defined)

    @subscribes_to.validator
    def _check_topic(self, attribute, value) -> None:
        _layer_name(value)

    @property
    def name(self) -> str:
        return _layer_name(self.subscribes_to)


@attrs.define(kw_only=True)
class MapConfig:
    map_name: str = attrs.field(default="map", validator=[attrs.validators.instance_of(str), attrs.validators.min_len(3)])
    distance_func: str = attrs.field(default="l2", validator=attrs.validators.in_(DISTANCES))


class MapEncoder:
    """Writes layer observations into the ``map_name`` collection of a ChromaClient."""

    def __init__(self, layers: Sequence[MapLayer], db_client: Any, config: MapConfig | None = None,
                 resolution: float | None = None) -> None:
        layers = list(layers)
        if not layers or not all(isinstance(layer, MapLayer) for layer in layers):
            raise ValueError("layers: expected a non-empty list of MapLayer")
        names = [layer.name for layer in layers]
        if len(set(names)) != len(names):
            raise ValueError(f"layers: each topic may feed one layer only, got {names}")
        self.layers = {layer.name: layer for layer in layers}
        self.db = db_client
        self.config = config or MapConfig()
        self.resolution: float | None = None
        if resolution is not None:
            self.set_resolution(resolution)

    def set_resolution(self, resolution: float) -> None:
        """The occupancy-grid resolution (m / cell), normally taken from the map topic."""
        if isinstance(resolution, bool) or not isinstance(resolution, (int, float)) or not resolution > 0:
            raise ValueError(f"map resolution: expected a positive number of metres, got {resolution!r}")
        self.resolution = float(resolution)

    def _layer(self, name: str) -> MapLayer:
        layer = self.layers.get(name)
        if layer is None:
            raise KeyError(f"unknown map layer {name!r}; layers are {sorted(self.layers)}")
        return layer

    def cells(self, layer_name: str, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(integer x/y cell indices (n, 2), coordinates (n, 3)) for an (n, 3) array of positions.

        The occupancy grid is planar, so x and y snap to the cell centre and z is kept as
        observed.
        """
        if self.resolution is None:
            raise RuntimeError("map resolution unknown: call set_resolution() (no map received yet)")
        size = self.resolution * self._layer(layer_name).resolution_multiple
        positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
        # The epsilon keeps positions on a cell edge (1.2 / 0.15 = 7.999...) in the upper cell.
        index = np.floor(positions[:, :2] / size + 1e-9).astype(np.int64)
        coordinates = positions.copy()
        coordinates[:, :2] = (index + 0.5) * size
        return index, np.round(coordinates, 6)

    def encode(self, layer_name: str, text: str, position: Any, timestamp: float | None = None) -> str | None:
        """Store one observation; returns its id (None for an empty text: nothing to remember)."""
        ids = self.encode_many(layer_name, [text], [position], [timestamp])
        return ids[0] if ids else None

    def encode_many(self, layer_name: str, texts: Sequence[str], positions: Sequence[Any] | np.ndarray,
                    timestamps: Sequence[float | None] | None = None,
                    embeddings: np.ndarray | None = None) -> list[str]:
        layer = self._layer(layer_name)
        texts = list(texts)
        if len(positions) != len(texts):
            raise ValueError(f"positions: expected {len(texts)} (one per text), got {len(positions)}")
        now = time.time()
        stamps = [now if t is None else float(t) for t in (timestamps or [None] * len(texts))]
        if len(stamps) != len(texts):
            raise ValueError(f"timestamps: expected {len(texts)} (one per text), got {len(stamps)}")
        keep = [i for i, t in enumerate(texts) if isinstance(t, str) and t.strip()]
        if not keep:
            return []
        points = np.stack([_position(positions[i]) for i in keep])
        index, centres = self.cells(layer_name, points)
        ids: list[str] = []
        metadatas: list[dict] = []
        documents: list[str] = []
        source: list[int] = []
        seen: dict[str, int] = {}
        for row, i in enumerate(keep):
            cell = ":".join(str(v) for v in index[row])
            entry_id = f"{layer.name}:{cell}"
            if layer.temporal_change:
                entry_id += f":{int(round(stamps[i] * 1e6))}"  # microseconds: unique per observation
            meta = {"coordinates": centres[row].tolist(), "layer_name": layer.name,
                    "timestamp": stamps[i], "temporal_change": layer.temporal_change}
            if entry_id in seen:  # same cell twice in one batch: the later observation wins
                j = seen[entry_id]
                documents[j], metadatas[j], source[j] = texts[i], meta, i
                continue
            seen[entry_id] = len(ids)
            ids.append(entry_id)
            documents.append(texts[i])
            metadatas.append(meta)
            source.append(i)
        vectors = None
        if embeddings is not None:
            all_vectors = np.asarray(embeddings, dtype=np.float32)
            if all_vectors.ndim != 2 or all_vectors.shape[0] != len(texts):
                raise ValueError(f"embeddings: expected {len(texts)} rows, got shape {all_vectors.shape}")
            vectors = all_vectors[source]
        self.db.upsert(self.config.map_name, documents, metadatas=metadatas, ids=ids,
                       distance_func=self.config.distance_func, embeddings=vectors)
        return ids

    def add_pre_defined(self, timestamp: float | None = None) -> list[str]:
        """Store every layer's pre-defined (position, text) points; idempotent across restarts."""
        stamp = time.time() if timestamp is None else float(timestamp)
        ids: list[str] = []
        for layer in self.layers.values():
            if not layer.pre_defined:
                continue
            points = np.stack([p for p, _ in layer.pre_defined])
            _, centres = self.cells(layer.name, points)
            layer_ids = [f"{layer.name}:pre_defined:{i}" for i in range(len(layer.pre_defined))]
            metadatas = [{"coordinates": centres[i].tolist(), "layer_name": layer.name, "timestamp": stamp,
                          "temporal_change": layer.temporal_change} for i in range(len(layer_ids))]
            self.db.upsert(self.config.map_name, [t for _, t in layer.pre_defined], metadatas=metadatas,
                           ids=layer_ids, distance_func=self.config.distance_func)
            ids += layer_ids
        return ids

