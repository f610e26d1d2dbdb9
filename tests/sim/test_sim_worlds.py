import json

import numpy as np
import pytest

from emos.actors.sim import Lidar, LidarConfig, SimClock, World
from emos.actors.sim.barn_worlds import BARN_CYLINDER_RADIUS, load_barn_worlds, parse_indices
from emos.actors.sim.builders import from_barn, house_shapes
from emos.actors.sim.mapfile import map_to_boxes, merge_cells, read_ros_map

pytestmark = pytest.mark.sim


def _barn_file(tmp_path, worlds):
    path = tmp_path / "worlds.json"
    path.write_text(json.dumps({str(k): v for k, v in worlds.items()}))
    return path


def test_barn_world_puts_cylinders_where_the_file_says(tmp_path, make_world):
    cylinders = [[-2.0, 5.0], [-3.1, 6.2], [-1.0, 8.0]]
    path = _barn_file(tmp_path, {7: {"cylinders": cylinders, "path_length": 10.0}})
    world = from_barn(7, worlds_file=path, clock=SimClock(mode="lockstep"))
    try:
        world.step()
        assert len(world.shapes) == 3
        # Probe each cylinder with rays from four sides at 1 m: surface at 1 - r.
        for cx, cy in cylinders:
            for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1)):
                start = [cx + dx, cy + dy, 0.5]
                end = [cx, cy, 0.5]
                hit = world.client.rayTest(start, end)[0]
                assert hit[0] >= 0
                assert hit[2] == pytest.approx(1.0 - BARN_CYLINDER_RADIUS, abs=BARN_CYLINDER_RADIUS * 0.02 + 1e-4)
        # And nothing stands between them.
        assert world.client.rayTest([-2.5, 3.0, 0.5], [-2.5, 4.5, 0.5])[0][0] == -1
    finally:
        world.close()


def test_the_shipped_barn_file_loads_and_selections_parse():
    worlds = load_barn_worlds()
    assert len(worlds) == 250
    assert all(i % 6 != 0 for i in worlds)
    w1 = worlds[1]
    assert w1.cylinders.shape[1] == 2 and w1.path_length > 10
    assert parse_indices("1,2,5-9") == [1, 2, 5, 6, 7, 8, 9]
    assert parse_indices("3, 3,1") == [3, 1]
    for bad in ("", "a", "9-5", "1,,x"):
        with pytest.raises(ValueError):
            parse_indices(bad)


def test_barn_file_errors_are_clear(tmp_path):
    with pytest.raises(FileNotFoundError, match="BARN world file not found"):
        load_barn_worlds(tmp_path / "nope.json")
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"1": {"cylinders": [[0, 0]]}}))
    with pytest.raises(ValueError, match="path_length"):
        load_barn_worlds(bad)


def test_merge_cells_covers_exactly_the_occupied_cells():
    rng = np.random.default_rng(3)
    for _ in range(20):
        grid = rng.random((30, 40)) < 0.3
        grid[5:15, 10:30] = True  # a solid block should become few rectangles
        rects = merge_cells(grid)
        cover = np.zeros(grid.shape, dtype=int)
        for r0, c0, r1, c1 in rects:
            cover[r0:r1, c0:c1] += 1
        np.testing.assert_array_equal(cover, grid.astype(int))  # exact and non-overlapping
    room = np.zeros((200, 200), dtype=bool)
    room[0, :] = room[-1, :] = room[:, 0] = room[:, -1] = True
    room[100, 20:180] = True
    assert len(merge_cells(room)) <= 6


def _write_map(tmp_path, pixels, resolution=0.05, origin=(-1.0, -2.0, 0.0)):
    from PIL import Image

    Image.fromarray(pixels).save(tmp_path / "room.pgm")
    (tmp_path / "room.yaml").write_text(
        f"image: room.pgm\nresolution: {resolution}\norigin: [{origin[0]}, {origin[1]}, {origin[2]}]\n"
        "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")
    return tmp_path / "room.yaml"


def test_ros_map_walls_are_extruded_in_the_right_place(tmp_path, make_world):
    pixels = np.full((200, 200), 254, dtype=np.uint8)  # 10 x 10 m, free
    pixels[:, 150:152] = 0  # a wall two cells thick, columns 150-151: x from 6.5 to 6.6 m
    pixels[:40, :] = 0  # the top 40 rows (top of the image = high y): y from 6 to 8 m
    yaml_path = _write_map(tmp_path, pixels)
    occ = read_ros_map(yaml_path)
    assert occ.occupied.shape == (200, 200)
    boxes = map_to_boxes(occ)
    assert len(boxes) <= 3
    world = World.from_map(yaml_path, clock=SimClock(mode="lockstep"))
    try:
        robot = world.add_robot("jackal", (2.0, 0.0, 0.0))
        lidar = world.add_sensor(Lidar(robot, LidarConfig(fov_deg=90, beams=3)))  # -45, 0, +45 deg
        world.step()
        assert lidar.latest.ranges[1] == pytest.approx(6.5 - 2.0, abs=1e-3)  # east wall (origin x = -1)
    finally:
        world.close()
    robot_view = World.from_map(yaml_path, clock=SimClock(mode="lockstep"))
    try:
        r = robot_view.add_robot("jackal", (2.0, 0.0, np.pi / 2))
        lidar = robot_view.add_sensor(Lidar(r, LidarConfig(fov_deg=2, beams=3)))
        robot_view.step()
        assert lidar.latest.ranges[1] == pytest.approx(6.0, abs=1e-3)  # north block starts at y = 6
    finally:
        robot_view.close()


def test_ros_map_errors_name_the_problem(tmp_path):
    with pytest.raises(ValueError, match="missing.yaml"):
        read_ros_map(tmp_path / "missing.yaml")
    (tmp_path / "a.yaml").write_text("image: a.pgm\n")
    with pytest.raises(ValueError, match="resolution"):
        read_ros_map(tmp_path / "a.yaml")
    (tmp_path / "b.yaml").write_text(
        "image: nothere.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n"
    )
    with pytest.raises(ValueError, match="map image not found"):
        read_ros_map(tmp_path / "b.yaml")


def test_demo_house_has_rooms_with_doorways_a_robot_drives_through(make_world):
    world = World.demo_house(clock=SimClock(mode="lockstep"))
    try:
        assert len(house_shapes()) == len(world.shapes) >= 10
        # From the spawn room, drive north through the doorway at x in [2, 3] on y = 4.
        robot = world.add_robot("jackal", (2.5, 2.0, np.pi / 2))
        robot.command(1.0)
        world.run_for(3.0)
        assert robot.pose[1] > 4.5
        assert not robot.collided
        # A robot driving north at x = 1 meets the wall at y = 4 - 0.06.
        blocked = world.add_robot("turtlebot3", (1.0, 2.0, np.pi / 2))
        blocked.command(0.22)
        world.run_for(12.0)
        assert blocked.collided
        assert blocked.pose[1] + blocked.spec.length / 2 == pytest.approx(4.0 - 0.06, abs=0.02)
    finally:
        world.close()


def test_world_add_rejects_wrong_types(make_world):
    world = make_world()
    with pytest.raises(TypeError, match="World.add"):
        world.add("box")
    with pytest.raises(TypeError, match="World.add"):
        world.add([1, 2])
