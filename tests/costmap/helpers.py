"""Maps and masks for the costmap tests."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from emos.actors.nav.costmap import Zone
from emos.actors.nav.costmap.mask_io import write_mask
from emos.actors.nav.maps import OccupancyGridMap, save_map

RES = 0.05
ROOM = (6.0, 4.0)  # an empty walled room, metres
#: across the straight line (1, 1) -> (4.5, 1): the way round is above it
KEEPOUT = Zone(name="wet_floor", kind="keepout", polygon=((2.5, 0.0), (3.5, 0.0), (3.5, 2.8), (2.5, 2.8)))


def room_grid() -> OccupancyGridMap:
    rows, cols = int(ROOM[1] / RES), int(ROOM[0] / RES)
    data = np.zeros((rows, cols), dtype=np.int8)
    data[:2, :] = data[-2:, :] = 100
    data[:, :2] = data[:, -2:] = 100
    return OccupancyGridMap(data=data, resolution=RES, origin=(0.0, 0.0, 0.0))


def write_room(folder: Path) -> tuple[str, str]:
    """(map YAML, keepout mask YAML) of the room."""
    grid = room_grid()
    return str(save_map(grid, folder / "room.yaml")), str(write_mask(folder / "keepout.yaml", [KEEPOUT], "keepout", grid))
