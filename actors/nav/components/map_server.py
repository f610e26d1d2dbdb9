"""``MapServer``: the global map from a file, published as a TRANSIENT_LOCAL OccupancyGrid.

Reads a map_server YAML (+ PGM/PNG) or a PCD point cloud (a height slice projected onto a grid
of ``grid_resolution``). A missing or malformed file fails configuration with an error naming
the file. ``map_file_read_rate`` > 0 re-reads the file at that rate and republishes it when it
changed. The ``<name>/save_map`` service (``Save2dMapToFile``) writes the map as YAML + PGM.
"""
from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from attrs import define, field

from emos.config.qos import TRANSIENT_LOCAL, QoSConfig
from emos.config.validators import in_range
from emos.core import clock
from emos.core.keyed import AllowedTopic
from emos.io.topic import Topic
from emos.msgs.sensor import PointCloud2
from emos.msgs.std import Header

from ..maps import MapFileError, load_map, save_map
from ..maps.grid import OccupancyGridMap
from ..maps.pcd import cloud_to_grid, read_pcd
from .base import NavComponent, NavComponentConfig, rate_field
from .convert import grid_msg
from .interfaces import SaveMapRequest, SaveMapResponse

__all__ = ["MapServer", "MapServerConfig"]


@define(kw_only=True)
class MapServerConfig(NavComponentConfig):
    """``map_file_path``: a ``.yaml`` (map_server) or ``.pcd`` file. ``map_file_read_rate`` (Hz):
    how often to re-read it (0: once). ``grid_resolution`` (m), ``min_height``/``max_height`` (m):
    how a point cloud becomes a grid. ``pc_publish_row``: also publish the cloud on
    ``spatial_sensor``. ``custom_map_frame``: frame of the published map (default
    ``frames.world``). ``map_file_folder``: where ``save_map`` writes by default."""

    loop_rate: float = rate_field(1.0)
    map_file_path: str = field(default="")
    map_file_read_rate: float = field(default=0.0, validator=in_range(min_value=0.0, max_value=1e3))
    grid_resolution: float = field(default=0.05, validator=in_range(min_value=1e-3, max_value=100.0))
    min_height: float = field(default=0.05)
    max_height: float = field(default=2.0)
    pc_publish_row: bool = field(default=False)
    custom_map_frame: str = field(default="")
    map_file_folder: str = field(default="")


class MapServer(NavComponent):
    allowed_inputs: ClassVar[Mapping[str, AllowedTopic]] = {}
    allowed_outputs: ClassVar[Mapping[str, AllowedTopic]] = {
        "global_map": AllowedTopic(types=("OccupancyGrid",), default=Topic(name="/map", msg_type="OccupancyGrid", qos_profile=QoSConfig(durability=TRANSIENT_LOCAL)), required=True),
        "spatial_sensor": AllowedTopic(types=("PointCloud2",), default=Topic(name="/row_point_cloud", msg_type="PointCloud2")),
    }
    key_aliases: ClassVar[Mapping[str, str]] = {"map": "global_map"}
    config: MapServerConfig

    @classmethod
    def config_class(cls) -> type[MapServerConfig]:
        return MapServerConfig

    # -- loading ---------------------------------------------------------------------------------------
    def _frame(self) -> str:
        return self.config.custom_map_frame or self.config.frames.world

    def load(self) -> tuple[OccupancyGridMap, np.ndarray | None]:
        """Read the configured file (raises MapFileError naming it)."""
        path = self.config.map_file_path
        if not path:
            raise MapFileError(f"component {self.component_name!r}: MapServerConfig.map_file_path is not set")
        p = Path(os.path.expanduser(path))
        if not p.exists():
            raise MapFileError(f"component {self.component_name!r}: map file {p} does not exist")
        if p.suffix.lower() == ".pcd":
            cloud = read_pcd(p)
            if len(cloud) == 0:
                raise MapFileError(f"{p}: the point cloud has no finite points")
            return cloud_to_grid(cloud, self.config.grid_resolution, self.config.min_height, self.config.max_height, frame_id=self._frame()), cloud
        if p.suffix.lower() not in (".yaml", ".yml"):
            raise MapFileError(f"{p}: unsupported map file type {p.suffix!r}; expected .yaml (map_server) or .pcd")
        return load_map(p), None

    def custom_on_configure(self) -> None:
        self._grid, self._cloud = self.load()  # fails the configuration with the file named
        self._mtime = self._file_mtime()
        self._since_read = 0.0
        self.create_service(f"{self.component_name}/save_map", SaveMapRequest, SaveMapResponse, self._save)

    def custom_on_activate(self) -> None:
        self._publish()

    def _file_mtime(self) -> float:
        try:
            return os.stat(os.path.expanduser(self.config.map_file_path)).st_mtime
        except OSError:
            return -1.0

    def _publish(self) -> None:
        g = self._grid
        self.publish(self.required_out_topic("global_map"), grid_msg(g.data, g.resolution, g.origin, self._frame()))
        out = self.get_out_topic("spatial_sensor")
        if self.config.pc_publish_row and self._cloud is not None and out is not None:
            self.publish(out, PointCloud2.from_xyz(self._cloud, Header(stamp=clock.stamp(), frame_id=self._frame())))

    def _execution_step(self, msg: Any = None, topic: Any = None, **kwargs: Any) -> None:
        rate = self.config.map_file_read_rate
        if rate > 0:
            self._since_read += 1.0 / self.config.loop_rate
            if self._since_read >= 1.0 / rate:
                self._since_read = 0.0
                mtime = self._file_mtime()
                if mtime != self._mtime:
                    try:
                        self._grid, self._cloud = self.load()
                    except (MapFileError, ValueError) as exc:
                        self.health_status.set_fail_component(component_names=[self.component_name], message=str(exc))
                        self.get_logger().error("[%s] keeping the previous map: %s", self.component_name, exc)
                        return
                    self._mtime = mtime
                    self._publish()
        self.health_status.set_healthy()

    # -- saving ---------------------------------------------------------------------------------------
    def _save(self, request: SaveMapRequest) -> SaveMapResponse:
        folder = request.file_location or self.config.map_file_folder or "."
        name = request.file_name or "map"
        if "/" in name or name.startswith("."):
            return SaveMapResponse(success=False, message=f"file_name must be a plain name, got {name!r}")
        try:
            path = save_map(self._grid, Path(os.path.expanduser(folder)) / f"{name}.yaml")
        except (OSError, ValueError) as exc:
            return SaveMapResponse(success=False, message=f"cannot save the map to {folder}/{name}.yaml: {exc}")
        return SaveMapResponse(success=True, message="saved", path=str(path))
