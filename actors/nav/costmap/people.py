"""The people layer: a soft cost where people have walked, so global plans keep off their way.

A robot that shares a house with a walking person meets them where its route runs along theirs:
the longer that stretch, the longer the robot is in the way (the passage guard,
:mod:`emos.actors.nav.missions.passages`, can only hold it before the stretch while the person
would be there). With this layer the Planner's grid planner (``CostToGo``) costs the cells near
where people walked ``1 + weight`` times their length, so a route crosses their way rather than
following it, and waits off it.

Nav2 has no such layer (ROS 1's ``social_navigation_layers`` put a proxemic cost around the
people seen *now*); this one is fed the band the Behaviors remember: the tracked movers'
centres over the last ``PassageGuardConfig.memory`` s (never ground truth), published as an
``OccupancyGrid`` in the world frame with :data:`WALKED` on each 5 cm cell a centre was recorded
in (:func:`band_grid`). The Planner takes it on its ``people`` input.
"""
from __future__ import annotations

import numpy as np
from attrs import define, field

from emos.config import validators as V

from ..maps.grid import OccupancyGridMap

__all__ = ["WALKED", "PeopleLayerConfig", "band_grid", "people_cost", "walked_points"]

#: the value of a cell a person's centre was recorded in (OccupancyGrid: 0..100)
WALKED = 100
BAND_RESOLUTION = 0.05  # m: the band's cells (MoverMemory.band_cells, lasting_band_cells)


@define(kw_only=True, frozen=True)
class PeopleLayerConfig:
    """``enabled``: plan with the people layer (the Planner needs the ``CostToGo`` grid planner and
    a ``people`` input). ``weight``: the extra cost of a cell within ``inflation`` m of where a
    person walked (1 + weight times its length; 3: a path along the band costs four times as
    much as one beside it, so it crosses the band where it must). ``inflation`` (m): the robot's
    and a person's radii plus a margin, as the passage guard's ``band_clearance``. ``fade`` (m):
    beyond it the cost falls linearly to 0 (a smooth field: the plan does not hug the edge)."""

    enabled: bool = field(default=False, validator=V.instance_of(bool))
    weight: float = field(default=3.0, validator=V.number(ge=0, le=1000, finite=True, what="cost per metre"))
    inflation: float = field(default=0.55, validator=V.number(ge=0, le=5, finite=True, what="metres"))
    fade: float = field(default=0.3, validator=V.number(gt=0, le=5, finite=True, what="metres"))


def band_grid(cells: np.ndarray, resolution: float = BAND_RESOLUTION) -> tuple[np.ndarray, tuple[float, float, float]]:
    """The band (``cells``: (K, 2) world centres of the cells people walked) as an OccupancyGrid's
    data (rows, cols; :data:`WALKED` on walked cells, 0 elsewhere) and origin (x, y, 0) of the
    smallest grid holding it; a 1 x 1 grid of 0 when nothing was walked."""
    cells = np.asarray(cells, dtype=float).reshape(-1, 2)
    if len(cells) == 0:
        return np.zeros((1, 1), dtype=np.int8), (0.0, 0.0, 0.0)
    ij = np.round(cells / resolution).astype(np.int64)  # the centres are multiples of the resolution
    lo = ij.min(axis=0)
    shape = tuple((ij.max(axis=0) - lo + 1)[::-1])
    data = np.zeros(shape, dtype=np.int8)
    data[ij[:, 1] - lo[1], ij[:, 0] - lo[0]] = WALKED
    # Cell (0, 0) is centred on the lowest centre.
    return data, (float((lo[0] - 0.5) * resolution), float((lo[1] - 0.5) * resolution), 0.0)


def walked_points(band: OccupancyGridMap) -> np.ndarray:
    """(K, 2) world centres of the cells of a received band grid that people walked (value >= 50)."""
    rows, cols = np.nonzero(band.data >= WALKED // 2)
    return band.grid_to_world(np.c_[cols, rows]) if len(rows) else np.zeros((0, 2))


def people_cost(grid: OccupancyGridMap, walked: np.ndarray, config: PeopleLayerConfig) -> np.ndarray:
    """The layer's extra cost on ``grid``'s cells (its shape): ``weight`` within ``inflation`` m of
    a ``walked`` point (N, 2 world), falling linearly to 0 over ``fade`` m beyond; walked points
    off the map are dropped."""
    from scipy import ndimage

    cost = np.zeros(grid.data.shape)
    walked = np.asarray(walked, dtype=float).reshape(-1, 2)
    if len(walked) == 0 or config.weight == 0:
        return cost
    cells = grid.world_to_grid(walked)
    inside = grid.in_bounds(cells)
    if not inside.any():
        return cost
    mark = np.zeros(grid.data.shape, dtype=bool)
    mark[cells[inside, 1], cells[inside, 0]] = True
    distance = ndimage.distance_transform_edt(~mark) * grid.resolution
    result: np.ndarray = config.weight * np.clip((config.inflation + config.fade - distance) / config.fade, 0.0, 1.0)
    return result
