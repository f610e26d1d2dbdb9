"""The kompass_sim maps the spec's navigation recipes load (issue 33 item 3): they are the generator's
output, they load as ROS maps, every goal the recipes send or a user clicks lies in free space at
the robot's footprint clearance and is reachable from where the robot starts, and the Simulator
extrudes the same walls the map has."""
from __future__ import annotations

import ast
import math
import re
from pathlib import Path

import numpy as np
import pytest

from emos.actors.nav.maps import distance_map, load_map
from emos.actors.sim.data.kompass_sim import generate_maps
from emos.packages import get_package_share_directory
from tests.runtime.helpers import REPO

pytestmark = pytest.mark.unit

MAPS = Path(get_package_share_directory("kompass_sim")) / "maps"
WEBOTS, HOUSE = MAPS / "turtlebot3_webots.yaml", MAPS / "turtlebot3_gazebo_house.yaml"
BURGER_RADIUS = 0.1  # the webots recipes' robot: CYLINDER, geometry_params [0.1, 0.3]
WAFFLE_RADIUS = math.hypot(0.15, 0.15)  # the Gazebo recipe's: BOX 0.3 x 0.3, its circumscribed circle

# Where a user clicks (the spec's recipes take goals from clicks on the map): somewhere in each room.
WEBOTS_CLICKS = [(-0.6, -3.0), (2.0, -4.2), (2.0, -2.6), (0.0, 1.5), (1.8, 2.4), (0.3, 4.0), (3.0, 3.0)]
HOUSE_CLICKS = {
    "hall": (1.0, 0.4), "living room": (-2.5, 3.5), "top-left room": (-6.3, 3.0), "bottom-left room": (-6.3, -1.5),
    "middle room": (1.0, 3.0), "right wing": (4.5, 1.5), "right wing, far corner": (6.5, 4.0),
    "bottom-right room": (6.2, -1.2), "front yard": (-2.0, -2.5), "turtlebot3_gazebo's spawn": (-2.0, -0.5),
}


def _recipe(name: str) -> str:
    return (REPO / "recipes" / name).read_text()


def _spawn(source: str) -> tuple[float, float]:
    (spawn,) = re.findall(r"SimulatorConfig\(world=[^,]+, spawn=\(([^)]*)\)", source)
    x, y, _ = (s.strip() for s in spawn.split(","))
    return float(x), float(y)


def _goals_in_docstring(source: str) -> list[tuple[float, float]]:
    doc = ast.get_docstring(ast.parse(source)) or ""
    return [(float(x), float(y)) for x, y in re.findall(r'"x": (-?[\d.]+), "y": (-?[\d.]+)', doc)]


def _point_navigation_goals() -> list[tuple[float, float]]:
    tree = ast.parse(_recipe("point_navigation.py"))
    (node,) = [n for n in tree.body if isinstance(n, ast.Assign) and any(getattr(t, "id", "") == "GOALS" for t in n.targets)]
    return [tuple(map(float, g)) for g in ast.literal_eval(node.value)]


def _clearance_and_reach(yaml_path: Path, start: tuple[float, float], radius: float):
    """Metres from each cell to the nearest wall or unknown cell (the planner's view), and a
    function: is a point in the same free component as ``start`` for a robot of ``radius``."""
    from scipy import ndimage

    grid = load_map(yaml_path)
    dist = distance_map(grid, unknown_is_occupied=True)
    labels, _ = ndimage.label(dist > radius, structure=np.ones((3, 3)))

    def cell(p):
        c = grid.world_to_grid(np.asarray(p, dtype=float))
        assert grid.in_bounds(c), f"{p} is outside the map {yaml_path.name}"
        return int(c[1]), int(c[0])

    home = labels[cell(start)]
    assert home > 0, f"the start {start} of {yaml_path.name} is not clear for a robot of radius {radius} m"
    return (lambda p: float(dist[cell(p)])), (lambda p: labels[cell(p)] == home)


def test_the_shipped_maps_are_the_generators_output(tmp_path):
    written = generate_maps.write(tmp_path)
    assert sorted(p.name for p in written) == ["turtlebot3_gazebo_house.yaml", "turtlebot3_webots.yaml"]
    for path in written:
        for shipped, fresh in ((MAPS / path.name, path), (MAPS / path.with_suffix(".pgm").name, path.with_suffix(".pgm"))):
            assert shipped.read_bytes() == fresh.read_bytes(), f"{shipped.name} differs: run python -m {generate_maps.__name__}"
            assert shipped.stat().st_size < 80_000  # small files


def test_the_maps_load_with_the_worlds_dimensions():
    webots, house = load_map(WEBOTS), load_map(HOUSE)
    assert webots.resolution == house.resolution == 0.05
    # The arena's floor: 5 x 10 m (Webots' x 5..10 shifted to the robot's start at 6.36).
    free = np.argwhere(webots.data == 0)
    (x0, y0), (x1, y1) = webots.grid_to_world(free[:, ::-1].min(axis=0)), webots.grid_to_world(free[:, ::-1].max(axis=0))
    # Cell centres between the walls' faces: x -1.26..3.64 (the left wall's centre is the floor's
    # edge), y -5..5.
    assert x1 - x0 == pytest.approx(4.85, abs=0.06) and y1 - y0 == pytest.approx(9.95, abs=0.06)
    # The house: 15 x 10.5 m between its outer walls' centre lines, the robot's spawn inside.
    xmin, ymin, xmax, ymax = house.world_bounds()
    assert xmin < -7.5 and xmax > 7.5 and ymin < -5.3 and ymax > 5.3
    assert house.values_at(np.array([[0.1, 0.2]]))[0] == 0 and webots.values_at(np.array([[0.0, 0.0]]))[0] == 0
    # A map the MapServer reads is a map the Simulator reads: same grid, walls where it says 100.
    from emos.actors.sim.mapfile import read_ros_map

    assert np.array_equal(read_ros_map(HOUSE).occupied, house.data >= 65)


@pytest.mark.parametrize("recipe", ["point_navigation.py", "nav_quick_start.py", "path_recording.py"])
def test_the_recipes_goals_are_free_at_the_footprint_clearance_and_reachable(recipe):
    source = _recipe(recipe)
    assert 'get_package_share_directory(package_name="kompass_sim")' in source
    assert '"maps", "turtlebot3_webots.yaml"' in source
    goals = _point_navigation_goals() if recipe == "point_navigation.py" else _goals_in_docstring(source)
    assert goals, f"{recipe} names no goal"
    clearance, reachable = _clearance_and_reach(WEBOTS, _spawn(source), BURGER_RADIUS)
    for goal in goals:
        assert clearance(goal) > BURGER_RADIUS + 0.1, f"{recipe}: goal {goal} is {clearance(goal):.2f} m from a wall"
        assert reachable(goal), f"{recipe}: goal {goal} cannot be reached from the start"


def test_clicks_anywhere_in_the_arena_are_reachable():
    clearance, reachable = _clearance_and_reach(WEBOTS, (0.0, 0.0), BURGER_RADIUS)
    for click in WEBOTS_CLICKS:
        assert clearance(click) > BURGER_RADIUS and reachable(click), click


def test_every_room_of_the_house_is_reachable_by_the_waffle_from_its_spawn():
    clearance, reachable = _clearance_and_reach(HOUSE, (0.1, 0.2), WAFFLE_RADIUS)
    for room, click in HOUSE_CLICKS.items():
        assert clearance(click) > WAFFLE_RADIUS, f"{room} {click}: {clearance(click):.2f} m from a wall"
        assert reachable(click), f"the {room} {click} cannot be reached from the spawn (0.1, 0.2)"


def test_the_motion_tests_circles_stay_clear_of_the_furniture():
    """The motion-testing recipe's three circles (10 s each at half its limits, 0.2 m/s and
    0.2 rad/s: forward, inverse, backward) from its spawn stay off every wall."""
    source = _recipe("motion_testing.py")
    assert '"maps", "turtlebot3_webots.yaml"' in source
    (spawn,) = re.findall(r"SimulatorConfig\(world=[^,]+, spawn=\(([^)]*)\)", source)
    x, y, yaw = (float(eval(s, {"np": np})) for s in spawn.split(","))  # the recipe's own literal (np.pi / 2)
    clearance, _ = _clearance_and_reach(WEBOTS, (x, y), BURGER_RADIUS)
    dt, worst = 0.05, math.inf
    for v, w in ((0.2, 0.2), (-0.2, 0.2), (-0.2, -0.2)):
        for _ in range(int(10.0 / dt)):
            x, y, yaw = x + v * math.cos(yaw) * dt, y + v * math.sin(yaw) * dt, yaw + w * dt
            worst = min(worst, clearance((x, y)))
    assert worst > BURGER_RADIUS + 0.3  # past the DriveManager's slow-down zone


@pytest.mark.parametrize("yaml_path, spawn", [(WEBOTS, (0.0, 0.0)), (HOUSE, (0.1, 0.2))], ids=["webots", "house"])
def test_the_simulator_extrudes_the_walls_the_map_has(yaml_path, spawn):
    from emos.actors.sim.builders import from_map
    from emos.actors.sim.clock import SimClock
    from emos.actors.sim.sensors import Lidar, LidarConfig

    grid = load_map(yaml_path)
    world = from_map(yaml_path, clock=SimClock(mode="lockstep"))
    try:
        robot = world.add_robot("turtlebot3", (*spawn, 0.0))
        lidar = world.add_sensor(Lidar(robot, LidarConfig(fov_deg=360, beams=360, range_max=12.0)))
        world.step()
        scan = lidar.latest
        sim = scan.ranges.astype(float)
        # The same beams marched through the map: first cell at or above the occupied threshold.
        sx, sy, syaw = scan.sensor_pose
        angles = syaw + scan.angle_min + scan.angle_increment * np.arange(len(sim))
        steps = np.arange(scan.range_min, 12.0, 0.01)
        pts = np.stack([sx + np.cos(angles)[:, None] * steps, sy + np.sin(angles)[:, None] * steps], axis=-1)
        hit = grid.values_at(pts.reshape(-1, 2), outside=0).reshape(pts.shape[:2]) >= 65
        expected = np.where(hit.any(axis=1), steps[hit.argmax(axis=1)], np.inf)
    finally:
        world.close()
    both = np.isfinite(sim) & np.isfinite(expected)
    assert both.mean() > 0.9, "the walls round the robot are missing in the simulated world"
    assert np.array_equal(np.isfinite(sim), np.isfinite(expected))
    assert np.percentile(np.abs(sim[both] - expected[both]), 95) < 0.08  # within a cell
