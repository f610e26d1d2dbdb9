"""Generate the shipped ``rooms`` map: four rooms, doorways, furniture and a closed closet.

Run ``python -m emos.actors.nav.data.generate_rooms_map`` to rebuild ``rooms.yaml`` and
``rooms.pgm`` beside this file. The layout is written in metres in the map frame
(0..10 m on both axes, origin corner placed at world (-5, -5)), 200 x 200 cells at 0.05 m:

- outer walls 0.15 m thick, with a 0.2 m band of unknown space outside them;
- a cross of inner walls at x = 5 m and y = 5 m splitting four rooms, joined by 1 m doorways
  (west-south door in the vertical wall only in the lower half, one door in each half of
  the horizontal wall, and one more in the upper half of the vertical wall);
- a table and a shelf as furniture blocks;
- a 1.5 m closet in the north-east corner closed on all sides (its inside is free but
  unreachable: the planner must report failure, not crash).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from emos.actors.nav.maps import OccupancyGridMap, save_map

RESOLUTION = 0.05
SIZE_CELLS = 200
ORIGIN = (-5.0, -5.0, 0.0)
HERE = Path(__file__).resolve().parent


def _box(data: np.ndarray, x0: float, y0: float, x1: float, y1: float, value: int) -> None:
    """Fill the map-frame rectangle [x0, x1) x [y0, y1) (metres) with ``value``."""
    c0, c1 = int(round(x0 / RESOLUTION)), int(round(x1 / RESOLUTION))
    r0, r1 = int(round(y0 / RESOLUTION)), int(round(y1 / RESOLUTION))
    data[r0:r1, c0:c1] = value


def build_rooms_grid() -> OccupancyGridMap:
    data = np.full((SIZE_CELLS, SIZE_CELLS), -1, dtype=np.int8)
    # Known interior, then the outer walls (the outermost 0.2 m stays unknown).
    _box(data, 0.2, 0.2, 9.8, 9.8, 100)
    _box(data, 0.35, 0.35, 9.65, 9.65, 0)
    # Inner walls, 0.1 m thick.
    _box(data, 4.95, 0.35, 5.05, 9.65, 100)  # vertical
    _box(data, 0.35, 4.95, 9.65, 5.05, 100)  # horizontal
    # Doorways, 1 m wide.
    _box(data, 4.95, 1.5, 5.05, 2.5, 0)  # SW <-> SE
    _box(data, 4.95, 7.0, 5.05, 8.0, 0)  # NW <-> NE
    _box(data, 1.0, 4.95, 2.0, 5.05, 0)  # SW <-> NW
    _box(data, 6.5, 4.95, 7.5, 5.05, 0)  # SE <-> NE
    # Furniture.
    _box(data, 2.0, 2.5, 3.5, 3.5, 100)  # table in the SW room
    _box(data, 5.6, 5.6, 6.0, 8.5, 100)  # shelf along the NE room's west side
    _box(data, 7.0, 1.0, 8.5, 1.6, 100)  # cabinet in the SE room
    # Closed closet in the NE corner: walls on all four sides, free inside.
    _box(data, 8.0, 8.0, 9.65, 9.65, 100)
    _box(data, 8.1, 8.1, 9.65, 9.65, 0)
    _box(data, 9.55, 8.0, 9.65, 9.65, 100)
    _box(data, 8.0, 9.55, 9.65, 9.65, 100)
    return OccupancyGridMap(data=data, resolution=RESOLUTION, origin=ORIGIN)


def main() -> None:
    path = save_map(build_rooms_grid(), HERE / "rooms.yaml", mode="trinary")
    print(f"wrote {path} and {path.with_suffix('.pgm')}")


if __name__ == "__main__":
    main()
