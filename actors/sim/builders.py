"""Ready-made worlds: the demo house, a ROS map, a BARN world."""
from __future__ import annotations

from pathlib import Path
from typing import Any

from .barn_worlds import BARN_CYLINDER_HEIGHT, BARN_CYLINDER_RADIUS, BarnWorld, load_barn_worlds
from .mapfile import map_to_boxes, read_ros_map
from .primitives import Box, Cylinder, Shape, Wall
from .world import World

WALL = 0.12
# Wall ends are square and overlap by WALL / 2, so a doorway's clear width is DOOR - WALL (0.98 m).
DOOR = 1.1

# A 10 x 8 m flat: four rooms, doorways between them, some furniture. Spawn at (1.5, 1.5).
HOUSE_SPAWN = (1.5, 1.5, 0.0)


def house_shapes() -> list[Shape]:
    """The demo house as shapes (no file needed)."""
    wall_color = (0.85, 0.82, 0.75, 1.0)

    def wall(a: tuple[float, float], b: tuple[float, float]) -> Wall:
        return Wall(a, b, WALL, 1.2, wall_color)

    shapes: list[Shape] = [
        wall((0, 0), (10, 0)), wall((10, 0), (10, 8)), wall((10, 8), (0, 8)), wall((0, 8), (0, 0)),
        # Middle wall x=5 with a doorway at y in [2.7, 2.7 + DOOR] (clear of the walls at y=4).
        wall((5, 0), (5, 2.7)), wall((5, 2.7 + DOOR), (5, 8)),
        # Rooms split at y=4, doorways at x in [2, 2 + DOOR] (left) and [7.5, 7.5 + DOOR] (right).
        wall((0, 4), (2, 4)), wall((2 + DOOR, 4), (5, 4)),
        wall((5, 4), (7.5, 4)), wall((7.5 + DOOR, 4), (10, 4)),
    ]
    shapes += [
        Box((2.0, 6.3), (1.2, 0.8), 0.75, color=(0.55, 0.35, 0.2, 1.0)),  # table
        Box((8.0, 1.0), (2.0, 0.8), 0.8, color=(0.3, 0.3, 0.5, 1.0)),  # sofa
        Box((7.2, 6.5), (0.6, 1.6), 1.8, color=(0.5, 0.4, 0.3, 1.0)),  # shelf
        Cylinder((9.4, 7.4), 0.25, 0.9, color=(0.2, 0.6, 0.25, 1.0)),  # plant
        Cylinder((3.8, 1.2), 0.3, 0.5, color=(0.6, 0.6, 0.6, 1.0)),  # bin
    ]
    return shapes


# A charging dock: a V reflector (two arms meeting at the contacts, opening along the dock's
# yaw) that a scan sees from any approach. The robot's DockSpec (emos.actors.nav.docking)
# describes the same shape; keep the two in step.
DOCK_HALF_ANGLE_DEG, DOCK_ARM, DOCK_THICKNESS, DOCK_HEIGHT = 45.0, 0.4, 0.03, 0.5
HOUSE_DOCK = (0.1, 6.0, 0.0)  # against the left wall of the top-left room, opening into the room


def charging_dock(pose: tuple[float, float, float]) -> list[Shape]:
    """The dock's two arms as walls; ``pose`` = (x, y, yaw) of the apex and its opening direction."""
    import math

    x, y, yaw = (float(v) for v in pose)
    color = (0.1, 0.1, 0.1, 1.0)
    arms: list[Shape] = []
    for sign in (1.0, -1.0):
        a = yaw + sign * math.radians(DOCK_HALF_ANGLE_DEG)
        # Centre line of an arm; its square end overlaps the apex by half a thickness.
        arms.append(Wall((x, y), (x + DOCK_ARM * math.cos(a) - DOCK_THICKNESS / 2 * math.cos(a),
                                  y + DOCK_ARM * math.sin(a) - DOCK_THICKNESS / 2 * math.sin(a)),
                         DOCK_THICKNESS, DOCK_HEIGHT, color))
    return arms


def demo_house(**world_kwargs: Any) -> World:
    """A small house with four rooms and doorways; the robot fits through every door."""
    world = World(name="demo_house", **world_kwargs)
    world.add(house_shapes())
    world.spawn = HOUSE_SPAWN
    return world


def from_map(yaml_path: str | Path, wall_height: float = 1.0, **world_kwargs: Any) -> World:
    """Walls extruded from the occupied cells of a ROS map (merged into few boxes)."""
    occ = read_ros_map(yaml_path)
    world = World(name=Path(yaml_path).stem, **world_kwargs)
    world.add(map_to_boxes(occ, wall_height))
    world.occupancy_map = occ
    return world


def barn_shapes(entry: BarnWorld) -> list[Shape]:
    return [Cylinder((x, y), BARN_CYLINDER_RADIUS, BARN_CYLINDER_HEIGHT) for x, y in entry.cylinders]


def from_barn(world: int | BarnWorld, worlds_file: str | Path | None = None, **world_kwargs: Any) -> World:
    """A BARN world: its cylinders where the file puts them (robot and goal are the caller's)."""
    entry = world if isinstance(world, BarnWorld) else _barn_entry(int(world), worlds_file)
    sim = World(name=f"barn_{entry.idx}", **world_kwargs)
    sim.add(barn_shapes(entry))
    sim.barn = entry
    return sim


def _barn_entry(idx: int, worlds_file: str | Path | None) -> BarnWorld:
    worlds = load_barn_worlds(worlds_file)
    if idx not in worlds:
        raise KeyError(f"BARN world {idx} is not in the world file (it has {len(worlds)} worlds, "
                       f"indices {min(worlds)}..{max(worlds)})")
    return worlds[idx]
