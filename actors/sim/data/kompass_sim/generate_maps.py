"""Generate the ``kompass_sim`` maps (``maps/*.yaml`` + ``.pgm``) from the TurtleBot3 worlds' layouts.

    python -m emos.actors.sim.data.kompass_sim.generate_maps     # rewrites maps/ next to this file

Each world is a list of simulator shapes (walls, furniture) rasterized at 0.05 m the way the demo
house's map is (:func:`emos.actors.sim.rasterize.shapes_to_grid`: a cell is a wall when its centre
lies in a shape). Cells inside the world's floor are free, the rest unknown, so the planner
(which treats unknown as occupied) stays on the floor. The numbers are the worlds' own:

* ``turtlebot3_webots``: webots_ros2_turtlebot's ``turtlebot3_burger_example.wbt``: a 5 x 10 m
  floor (x 5..10, y -5..5 in Webots), 0.2 m walls, a door in the left wall (drawn closed: beyond
  it there is no floor), potted trees, a table, sofa, armchair, fridge, cabinet, radiator,
  floor light and cardboard boxes at their poses (footprints from the objects' default sizes).
  The robot starts at Webots (6.36, 0); the map's frame is its odometry frame, so everything
  is shifted by -6.36 m in x and the robot starts at (0, 0).
* ``turtlebot3_gazebo_house``: turtlebot3_gazebo's ``turtlebot3_house`` model, in its world
  frame: the 0.15 m walls from the model's collision boxes that reach the floor (lintels above
  doors are left out; window sills are walls), doorways 0.9 m wide, the front door at x 0.66..1.56
  on y = -0.175, the open front yard (x -5.15..4.9, y < -0.175) included, and the furniture
  (bookshelves, cabinets, cafe tables, trash cans, a table's four legs, the marble table, the
  mailbox). The rooms: bottom-left (x < -5.15, y -3.9..0.9), top-left, the living room
  (x -5.15..-0.05), the hall behind the front door, the middle room (x -0.05..2.3, y > 0.9), the
  right wing (x > 2.3, y > -0.175) and the bottom-right room (x > 4.9, y < -0.175).

A test (tests/spec_maps) checks the shipped files equal this output, so they never drift apart.
"""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import attrs
import numpy as np

from emos.actors.sim.primitives import Box, Cylinder, Shape

if TYPE_CHECKING:
    from emos.actors.nav.maps import OccupancyGridMap

RESOLUTION = 0.05
MAPS_DIR = Path(__file__).resolve().parent / "maps"


@attrs.define(frozen=True)
class TB3World:
    """One map: its shapes, the floor rectangles (free unless a shape covers them), the grid's
    origin and size (rows, cols), and the robot's start pose in the map frame."""

    name: str
    shapes: list[Shape]
    floor: list[tuple[float, float, float, float]]  # (x0, y0, x1, y1)
    origin: tuple[float, float]
    size: tuple[int, int]
    spawn: tuple[float, float, float]


def _rect(x0: float, y0: float, x1: float, y1: float) -> Box:
    return Box(((x0 + x1) / 2, (y0 + y1) / 2), (x1 - x0, y1 - y0), 1.0)


# -- webots_ros2 TurtleBot3 arena -------------------------------------------------------------
WEBOTS_SHIFT_X = -6.36  # the robot's start in the Webots world


def _webots_shapes() -> list[Shape]:
    def box(x: float, y: float, sx: float, sy: float) -> Box:
        return Box((x + WEBOTS_SHIFT_X, y), (sx, sy), 1.0)

    def pot(x: float, y: float, r: float = 0.2) -> Cylinder:
        return Cylinder((x + WEBOTS_SHIFT_X, y), r, 1.0)

    walls = [
        box(7.5, 5.1, 5.0, 0.2),  # top
        box(5.5, -5.1, 1.0, 0.2), box(6.5, -5.1, 1.0, 0.2), box(8.5, -5.1, 3.0, 0.2),  # bottom (wall, window, wall)
        box(10.1, 0.0, 0.2, 10.4),  # right
        box(5.0, 2.0, 0.2, 6.0), box(5.0, -3.5, 0.2, 3.0),  # left, either side of the door
        box(5.0, -1.5, 0.2, 1.0),  # the door, closed: no floor behind it
    ]
    furniture: list[Shape] = [
        pot(7.0, -4.0), pot(5.8, 3.3), pot(9.17, -1.7), pot(5.6, -4.5),  # potted trees
        box(7.33, 4.9, 0.9, 0.15),  # radiator against the top wall
        box(9.45, -2.5, 0.9, 1.0),  # cabinet against the right wall
        box(9.7, 4.7, 0.6, 0.6), box(9.0, 4.6, 0.6, 0.6), box(9.6, 4.0, 0.6, 0.6),  # cardboard boxes
        box(5.7, 4.64, 0.7, 0.7),  # fridge
        pot(8.84, 1.0),  # floor light
        box(9.0, -0.518, 0.9, 2.0),  # sofa, long side along y
        box(7.62, 1.03, 0.9, 0.9),  # armchair
        box(7.7, -0.52, 0.8, 1.3),  # table (1.3 x 0.8, turned along y)
    ]
    return walls + furniture


WEBOTS = TB3World(
    name="turtlebot3_webots",
    shapes=_webots_shapes(),
    floor=[(5.0 + WEBOTS_SHIFT_X, -5.0, 10.0 + WEBOTS_SHIFT_X, 5.0)],
    origin=(-2.0, -5.7),
    size=(228, 124),  # y -5.7..5.7, x -2.0..4.2
    spawn=(0.0, 0.0, 0.0),
)

# -- turtlebot3_gazebo house --------------------------------------------------------------------
HOUSE_WALL = 0.15


def _house_shapes() -> list[Shape]:
    def h(y: float, x0: float, x1: float) -> Box:  # a wall along x at y
        return _rect(x0, y - HOUSE_WALL / 2, x1, y + HOUSE_WALL / 2)

    def v(x: float, y0: float, y1: float) -> Box:  # a wall along y at x
        return _rect(x - HOUSE_WALL / 2, y0, x + HOUSE_WALL / 2, y1)

    walls = [
        h(5.272, -7.575, 7.578),  # top (Wall_81..84, window sills included)
        v(-7.5, -4.0, 5.35),  # left (Wall_85, Wall_86)
        v(7.5, -5.35, 5.25),  # right (Wall_95, Wall_96)
        h(-5.275, 4.825, 7.575),  # bottom of the bottom-right room (Wall_94)
        v(4.9, -5.35, -0.1),  # left of the bottom-right room (Wall_93)
        h(-3.925, -7.575, -5.075),  # bottom of the bottom-left room (Wall_87)
        v(-5.15, -3.996, 1.004),  # right of the bottom-left room (Wall_88)
        h(0.925, -7.575, -6.759), h(0.925, -5.859, -5.075),  # bottom-left | top-left, door (Wall_98)
        v(-5.15, 0.85, 2.108), v(-5.15, 4.524, 5.35),  # top-left | living room, 2.4 m opening (Wall_99)
        h(-0.175, -5.125, 0.662), h(-0.175, 1.562, 2.375),  # front, front door x 0.66..1.56 (Wall_108)
        h(-0.175, 2.225, 4.975),  # front of the right wing (Wall_92)
        h(-0.175, 4.825, 5.77), h(-0.175, 6.67, 7.575),  # right wing | bottom-right room, door (Wall_106)
        v(-0.05, 0.85, 5.35),  # living room | middle room (Wall_101)
        h(0.925, -0.125, 2.375),  # hall | middle room (Wall_90)
        v(2.3, 0.853, 1.0), v(2.3, -0.25, -0.047),  # hall | right wing, door y -0.05..0.85 (Wall_91)
        v(2.3, 0.85, 4.183), v(2.3, 5.083, 5.35),  # middle room | right wing, door y 4.18..5.08 (Wall_104)
    ]
    furniture: list[Shape] = [
        *(Box((x, 5.0), (0.92, 0.4), 1.2) for x in (-6.544, 4.724, 5.644)),  # bookshelves
        *(Box(c, (0.47, 0.47), 1.0) for c in ((-5.472, -1.576), (-5.473, -2.065), (-7.184, 1.248))),  # cabinets
        Cylinder((6.359, -3.192), 0.28, 0.8), Cylinder((6.359, -2.278), 0.28, 0.8),  # cafe tables (their bases)
        Cylinder((1.883, 1.912), 0.25, 0.75), Cylinder((-4.694, 4.894), 0.25, 0.75),  # trash cans
        *(Cylinder((-2.657 + dx, 2.424 + dy), 0.05, 1.0) for dx in (-0.68, 0.68) for dy in (-0.38, 0.38)),  # table legs
        Cylinder((4.883, 2.926), 0.3, 0.8),  # marble table
        Cylinder((0.883, -0.576), 0.15, 1.0),  # mailbox, in the yard before the front door
    ]
    return walls + furniture


HOUSE = TB3World(
    name="turtlebot3_gazebo_house",
    shapes=_house_shapes(),
    floor=[(-7.5, -5.275, 7.5, 5.272)],  # the house and its front yard
    origin=(-8.0, -5.8),
    size=(232, 320),  # y -5.8..5.8, x -8.0..8.0
    spawn=(0.1, 0.2, 0.0),
)

WORLDS = {w.name: w for w in (WEBOTS, HOUSE)}


def world_grid(world: TB3World) -> OccupancyGridMap:
    """The world as an ``OccupancyGridMap``: 100 in a shape, 0 on the floor, -1 elsewhere."""
    from emos.actors.nav.maps import OccupancyGridMap
    from emos.actors.sim.rasterize import shapes_to_grid

    occupied = shapes_to_grid(world.shapes, RESOLUTION, world.origin, world.size)
    rows, cols = world.size
    xs = world.origin[0] + (np.arange(cols) + 0.5) * RESOLUTION
    ys = world.origin[1] + (np.arange(rows) + 0.5) * RESOLUTION
    floor = np.zeros((rows, cols), dtype=bool)
    for x0, y0, x1, y1 in world.floor:
        floor |= ((ys[:, None] >= y0) & (ys[:, None] <= y1)) & ((xs[None, :] >= x0) & (xs[None, :] <= x1))
    data = np.where(occupied, 100, np.where(floor, 0, -1)).astype(np.int8)
    return OccupancyGridMap(data=data, resolution=RESOLUTION, origin=(*world.origin, 0.0))


def write(directory: Path | None = None) -> list[Path]:
    """Write every world's YAML + PGM into ``directory`` (default: the shipped ``maps/``)."""
    from emos.actors.nav.maps import save_map

    directory = directory or MAPS_DIR
    directory.mkdir(parents=True, exist_ok=True)
    return [save_map(world_grid(w), directory / f"{w.name}.yaml", image_name=f"{w.name}.pgm") for w in WORLDS.values()]


if __name__ == "__main__":
    for path in write():
        print(path)
