"""OMPL global planning on the shipped rooms map; every path checked independently."""
import math
import time

import numpy as np
import pytest

from emos.actors.nav.data import ROOMS_MAP_YAML
from emos.actors.nav.maps import OccupancyGridMap, load_map
from emos.actors.nav.planning import OMPLConfig, OMPLGeometricPlanner, available_planners
from emos.actors.nav.robot import RobotConfig, RobotGeometry, RobotType

pytestmark = pytest.mark.unit

RADIUS = 0.25
SW_ROOM = (-4.0, -4.0, 0.0)
NE_ROOM = (2.0, 2.0, math.pi / 2)
NW_ROOM = (-3.0, 3.0, -math.pi / 2)
CLOSET = (3.8, 3.8, 0.0)  # inside the closed NE closet: free but unreachable


@pytest.fixture(scope="module")
def rooms() -> OccupancyGridMap:
    return load_map(ROOMS_MAP_YAML)


def cylinder_robot(radius: float = RADIUS) -> RobotConfig:
    return RobotConfig(
        model_type=RobotType.DIFFERENTIAL_DRIVE,
        geometry_type=RobotGeometry.Type.CYLINDER,
        geometry_params=np.array([radius, 0.3]),
    )


def blocked_squares(grid: OccupancyGridMap) -> np.ndarray:
    """(K, 4) world boxes [xmin, ymin, xmax, ymax] of occupied and unknown cells (origin yaw 0)."""
    iy, ix = np.nonzero((grid.data >= 65) | (grid.data < 0))
    x0 = grid.origin[0] + ix * grid.resolution
    y0 = grid.origin[1] + iy * grid.resolution
    return np.column_stack((x0, y0, x0 + grid.resolution, y0 + grid.resolution))


def assert_disc_path_clear(path: np.ndarray, grid: OccupancyGridMap, radius: float) -> None:
    """Independent check (no fcl, no EDT): densify the path to 5 mm and compute the exact
    distance from every centre to every blocked cell square; all must exceed the radius."""
    seg = np.diff(path[:, :2], axis=0)
    n = np.maximum(np.ceil(np.hypot(seg[:, 0], seg[:, 1]) / 0.005), 1).astype(int)
    pts = np.concatenate(
        [path[i, :2] + np.linspace(0, 1, k, endpoint=False)[:, None] * seg[i] for i, k in enumerate(n)]
        + [path[-1:, :2]]
    )
    boxes = blocked_squares(grid)
    for chunk in np.array_split(pts, max(1, len(pts) // 500)):
        dx = np.maximum(np.maximum(boxes[None, :, 0] - chunk[:, None, 0], 0), chunk[:, None, 0] - boxes[None, :, 2])
        dy = np.maximum(np.maximum(boxes[None, :, 1] - chunk[:, None, 1], 0), chunk[:, None, 1] - boxes[None, :, 3])
        assert np.hypot(dx, dy).min() > radius, "path comes closer than the robot radius to an obstacle"


def assert_box_path_clear(path: np.ndarray, grid: OccupancyGridMap, length: float, width: float) -> None:
    """Independent check for a box robot: sample its footprint on a 1 cm lattice along a 1 cm /
    0.01 rad densified path and require that no sample falls in a blocked cell."""
    gx, gy = np.meshgrid(np.linspace(-length / 2, length / 2, int(length / 0.01) + 1),
                         np.linspace(-width / 2, width / 2, int(width / 0.01) + 1))
    body = np.column_stack((gx.ravel(), gy.ravel()))
    from emos.actors.nav.planning import interpolate_se2

    dense = interpolate_se2(path, 0.01, 0.01)
    c, s = np.cos(dense[:, 2]), np.sin(dense[:, 2])
    wx = dense[:, None, 0] + c[:, None] * body[None, :, 0] - s[:, None] * body[None, :, 1]
    wy = dense[:, None, 1] + s[:, None] * body[None, :, 0] + c[:, None] * body[None, :, 1]
    values = grid.values_at(np.stack((wx, wy), axis=-1), outside=-1)
    assert ((values >= 0) & (values < 65)).all(), "box footprint overlaps a blocked cell"


def check_endpoints(path: np.ndarray, start, goal, tol: float) -> None:
    assert np.allclose(path[0], start)
    assert math.hypot(path[-1, 0] - goal[0], path[-1, 1] - goal[1]) <= tol + 1e-9


@pytest.mark.parametrize("planner_id", ["ompl.geometric.RRTConnect", "KPIECE1", "LBKPIECE1", "BFMT", "RRT"])
def test_feasibility_planners_cross_doorways_without_collision(rooms, planner_id):
    planner = OMPLGeometricPlanner(OMPLConfig(planner_id=planner_id, planning_timeout=5.0), cylinder_robot())
    planner.set_map(rooms)
    result = planner.plan(SW_ROOM, NE_ROOM)
    assert result.solved, result.message
    assert result.status == "EXACT_SOLUTION"
    check_endpoints(result.path, SW_ROOM, NE_ROOM, 0.01)
    # Spacing is the configured resolution; the length is the planar polyline length.
    steps = np.hypot(*np.diff(result.path[:, :2], axis=0).T)
    assert steps.max() <= 0.05 + 1e-9
    assert result.length_m == pytest.approx(steps.sum())
    # Straight-line distance is 8.49 m but walls force a detour through two doorways.
    assert result.length_m > 9.0
    assert_disc_path_clear(result.path, rooms, RADIUS)


def test_optimizing_planner_uses_budget_and_finds_shorter_path(rooms):
    robot = cylinder_robot()
    quick = OMPLGeometricPlanner(OMPLConfig(planner_id="RRT", planning_timeout=2.0, simplify=False), robot)
    quick.set_map(rooms)
    best = OMPLGeometricPlanner(OMPLConfig(planner_id="RRTstar", planning_timeout=1.0), robot)
    best.set_map(rooms)
    r_best = best.plan(SW_ROOM, NE_ROOM)
    assert r_best.solved
    assert r_best.planning_time_s >= 0.9  # anytime planner keeps improving until the budget ends
    assert_disc_path_clear(r_best.path, rooms, RADIUS)
    r_quick = quick.plan(SW_ROOM, NE_ROOM)
    assert r_quick.solved
    assert r_best.length_m < r_quick.length_m


def test_box_robot_path_is_clear_for_its_rotating_footprint(rooms):
    robot = RobotConfig(
        model_type=RobotType.OMNI, geometry_type=RobotGeometry.Type.BOX, geometry_params=np.array([0.7, 0.3, 0.2])
    )
    planner = OMPLGeometricPlanner(OMPLConfig(planner_id="RRTConnect", planning_timeout=5.0), robot)
    planner.set_map(rooms)
    result = planner.plan((-4.0, -4.0, 0.0), (-3.0, 3.0, 0.0))
    assert result.solved, result.message
    assert_box_path_clear(result.path, rooms, 0.7, 0.3)


def test_goal_in_plain_sight_is_a_straight_line(rooms):
    planner = OMPLGeometricPlanner(OMPLConfig(planner_id="AORRTC", planning_timeout=0.3), cylinder_robot())
    planner.set_map(rooms)
    result = planner.plan(SW_ROOM, (-1.0, -4.0, 0.5))
    assert result.solved and result.message == "straight line"
    assert result.length_m == pytest.approx(3.0)
    assert np.allclose(result.path[-1], (-1.0, -4.0, 0.5))


def test_goal_without_heading_accepts_any_yaw(rooms):
    planner = OMPLGeometricPlanner(OMPLConfig(planner_id="RRTConnect", planning_timeout=5.0), cylinder_robot())
    planner.set_map(rooms)
    result = planner.plan(SW_ROOM, (1.5, -3.0))
    assert result.solved
    assert math.hypot(result.path[-1, 0] - 1.5, result.path[-1, 1] + 3.0) <= 0.01
    # In plain sight the robot arrives facing its direction of travel.
    straight = planner.plan(SW_ROOM, (-1.0, -3.0))
    assert straight.message == "straight line"
    assert straight.path[-1, 2] == pytest.approx(math.atan2(1.0, 3.0))


def test_unreachable_goal_fails_cleanly_within_the_timeout(rooms):
    planner = OMPLGeometricPlanner(OMPLConfig(planner_id="RRTConnect", planning_timeout=0.5), cylinder_robot(0.2))
    planner.set_map(rooms)
    t0 = time.perf_counter()
    result = planner.plan(SW_ROOM, CLOSET)
    elapsed = time.perf_counter() - t0
    assert not result.solved
    assert result.status == "TIMEOUT"
    assert result.path.shape == (0, 3)
    assert result.planning_time_s >= 0.5  # it searched for its whole budget...
    assert elapsed < 60  # ...and then gave up (a bound on a hang only: a loaded machine is slow)


def test_blocked_start_or_goal_and_bad_input(rooms):
    planner = OMPLGeometricPlanner(OMPLConfig(planner_id="RRTConnect", planning_timeout=0.5), cylinder_robot())
    planner.set_map(rooms)
    inside_table = (-2.25, -2.0, 0.0)  # the SW table
    assert planner.plan(inside_table, SW_ROOM).status == "INVALID_START"
    assert planner.plan(SW_ROOM, inside_table).status == "INVALID_GOAL"
    with pytest.raises(ValueError, match="outside the map"):
        planner.plan(SW_ROOM, (20.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="start"):
        planner.plan((0.0, float("nan"), 0.0), SW_ROOM)
    with pytest.raises(ValueError, match="goal"):
        planner.plan(SW_ROOM, (1.0,))
    fresh = OMPLGeometricPlanner(OMPLConfig(), cylinder_robot())
    with pytest.raises(RuntimeError, match="set_map"):
        fresh.plan(SW_ROOM, NE_ROOM)


def test_rotated_map_origin(rooms):
    # The same map placed at a rotated origin: a path still exists and stays clear in the
    # rotated frame (checked by mapping the path back into the map frame).
    yaw = 0.5
    rotated = OccupancyGridMap(data=rooms.data, resolution=rooms.resolution, origin=(1.0, 2.0, yaw))

    def to_world(p):
        xy = rotated.map_to_world(np.array([p[0] + 5.0, p[1] + 5.0]))
        return (xy[0], xy[1], p[2] + yaw)

    planner = OMPLGeometricPlanner(OMPLConfig(planner_id="RRTConnect", planning_timeout=5.0), cylinder_robot())
    planner.set_map(rotated)
    result = planner.plan(to_world(SW_ROOM), to_world(NE_ROOM))
    assert result.solved, result.message
    back = rotated.world_to_map(result.path[:, :2]) + np.array([-5.0, -5.0])
    assert_disc_path_clear(np.column_stack((back, result.path[:, 2])), rooms, RADIUS)


@pytest.mark.parametrize("planner_id", available_planners())
def test_every_available_planner_solves_a_short_query(rooms, planner_id):
    # Every planner stops at its first solution (anytime ones too: first_solution), so the
    # timeout only bounds a hang: a short budget failed PRM on a loaded machine.
    planner = OMPLGeometricPlanner(OMPLConfig(planner_id=planner_id, planning_timeout=120.0, first_solution=True), cylinder_robot())
    planner.set_map(rooms)
    # The SW table lies between these two poses, so this needs a real search.
    result = planner.plan((-4.0, -2.0, 0.0), (-1.0, -2.0, 0.0))
    assert result.solved, f"{planner_id}: {result.status} {result.message}"
    assert result.planner == planner_id
    assert result.planning_time_s < 60  # it stopped at its first solution, long before its budget
    assert result.message != "straight line"
    assert result.length_m > 3.05
    assert_disc_path_clear(result.path, rooms, RADIUS)


@pytest.mark.parametrize("seed", range(6))
def test_random_cluttered_maps_never_yield_a_colliding_path(seed):
    rng = np.random.default_rng(seed)
    data = np.zeros((80, 80), np.int8)
    for _ in range(30):
        x, y = rng.integers(0, 75, 2)
        data[y:y + rng.integers(1, 12), x:x + rng.integers(1, 12)] = 100
    data[:12, :12] = 0
    data[-12:, -12:] = 0
    grid = OccupancyGridMap(data=data, resolution=0.05, origin=(-2.0, -2.0, 0.0))
    radius = 0.08
    planner = OMPLGeometricPlanner(
        OMPLConfig(planner_id="RRTConnect", planning_timeout=60.0, unknown_is_occupied=False), cylinder_robot(radius)
    )
    planner.set_map(grid)
    start, goal = (-1.86, -1.86, 0.0), (1.86, 1.86, 0.0)
    result = planner.plan(start, goal)
    # These seeds all have a wide passage: RRTConnect solves each at its first try (the timeout
    # only bounds a hang).
    assert result.solved, result.status
    check_endpoints(result.path, start, goal, 0.01)
    assert_disc_path_clear(result.path, grid, radius)


def test_final_verification_rejects_a_path_through_a_wall(rooms):
    # The safety net behind OMPL: a candidate path that crosses the wall between the south
    # rooms (x = 0, away from its doorway) is refused, whatever produced it.
    planner = OMPLGeometricPlanner(OMPLConfig(planner_id="RRTConnect"), cylinder_robot())
    planner.set_map(rooms)
    through_wall = np.array([[-1.0, -4.0, 0.0], [1.0, -4.0, 0.0]])
    result = planner._finish(through_wall, "RRTConnect", 0.0, 0.0)
    assert not result.solved and result.status == "PATH_IN_COLLISION"
    assert result.path.shape == (0, 3)
    # Grazing the table edge (y = -2.5) by 1 cm is caught; passing 1 cm below it is fine.
    grazing = np.array([[-3.5, -2.74, 0.0], [-2.5, -2.74, 0.0]])
    assert not planner._finish(grazing, "RRTConnect", 0.0, 0.0).solved
    clear = np.array([[-3.5, -2.76, 0.0], [-2.5, -2.76, 0.0]])
    assert planner._finish(clear, "RRTConnect", 0.0, 0.0).solved


def test_cancel_from_another_thread(rooms):
    import threading

    robot = cylinder_robot()
    # An anytime planner keeps its best path when cancelled ...
    anytime = OMPLGeometricPlanner(OMPLConfig(planner_id="RRTstar", planning_timeout=30.0), robot)
    anytime.set_map(rooms)
    assert anytime.cancel() is False  # nothing running
    # Cancelled once it has had time to find a first path (milliseconds on an idle machine; 0.5 s
    # was not always enough with the cores busy, and a cancel before any path is the case below).
    timer = threading.Timer(3.0, anytime.cancel)
    timer.start()
    result = anytime.plan(SW_ROOM, NE_ROOM)
    # Ended by the cancel, not by its 30 s budget (the margin is for a loaded machine).
    assert result.solved and result.planning_time_s < 20.0
    assert_disc_path_clear(result.path, rooms, RADIUS)
    # ... a query that has nothing yet reports CANCELLED.
    stuck = OMPLGeometricPlanner(OMPLConfig(planner_id="RRTConnect", planning_timeout=30.0), cylinder_robot(0.2))
    stuck.set_map(rooms)
    threading.Timer(0.3, stuck.cancel).start()
    result = stuck.plan(SW_ROOM, CLOSET)
    assert not result.solved and result.status == "CANCELLED" and result.planning_time_s < 20.0  # not its 30 s budget
