"""Generate the shipped demo-house map from the simulator's own house shapes.

Run ``python -m emos.actors.sim.data.generate_house_map`` after changing
:func:`emos.actors.sim.builders.house_shapes`; a test checks that the shipped files equal
what this produces, so the two never drift apart.

The map covers x in [-0.5, 10.5] and y in [-0.5, 8.5] m at 0.05 m per cell: the house
(10 x 8 m) plus a 0.5 m band outside its outer walls, which is marked unknown.
"""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from emos.actors.nav.maps import OccupancyGridMap

RESOLUTION = 0.05
ORIGIN = (-0.5, -0.5, 0.0)
SIZE = (180, 220)  # rows (y), cols (x)
HOUSE_EXTENT = (0.0, 0.0, 10.0, 8.0)  # inside of the outer walls' centre lines


def house_grid() -> OccupancyGridMap:
    """The house as an ``OccupancyGridMap`` (0 free, 100 occupied, -1 outside the house)."""
    from emos.actors.nav.maps import OccupancyGridMap

    from ..builders import house_shapes
    from ..rasterize import shapes_to_grid

    occupied = shapes_to_grid(house_shapes(), RESOLUTION, ORIGIN[:2], SIZE)
    rows, cols = SIZE
    xs = ORIGIN[0] + (np.arange(cols) + 0.5) * RESOLUTION
    ys = ORIGIN[1] + (np.arange(rows) + 0.5) * RESOLUTION
    x0, y0, x1, y1 = HOUSE_EXTENT
    inside = ((ys[:, None] >= y0) & (ys[:, None] <= y1)) & ((xs[None, :] >= x0) & (xs[None, :] <= x1))
    data = np.where(occupied, 100, np.where(inside, 0, -1)).astype(np.int8)
    return OccupancyGridMap(data=data, resolution=RESOLUTION, origin=ORIGIN)


def write(directory: Path | None = None) -> Path:
    from emos.actors.nav.maps import save_map

    directory = directory or Path(__file__).resolve().parent
    return save_map(house_grid(), directory / "house.yaml", image_name="house.pgm")


if __name__ == "__main__":
    print(write())
