"""Bad input and faults on the navigation components, in real processes: NaN/inf and empty
scans, missing and malformed map files; and the MotionServer's recorded tests."""
from __future__ import annotations

import csv
import math
import time

import numpy as np
import pytest

from emos import msgs as M
from emos.core.health import HealthLevel
from tests.runtime.helpers import REPO, SystemUnderTest, wait_until

pytestmark = pytest.mark.process

HEADER = """
from emos.actors.nav.components import *
from emos.actors.nav import MapConfig
from tests.nav.components.fake_base import FakeBase
"""


def _system(tmp_path, body, components, **kw):
    return SystemUnderTest(tmp_path, HEADER + body, env={"PYTHONPATH": str(REPO)}, **kw).wait_up(timeout=60, components=components)


def _scan(ranges):
    return M.LaserScan(angle_min=-math.pi, angle_max=math.pi, angle_increment=2 * math.pi / max(len(ranges), 1),
                       range_min=0.05, range_max=10.0, ranges=np.asarray(ranges, dtype=np.float32))


def test_mapper_reports_empty_scans_and_ignores_nan_inf_beams(tmp_path):
    from emos.transport.pubsub import Publisher, Subscriber

    system = _system(tmp_path, """
mapper = LocalMapper(component_name="mapper", config=LocalMapperConfig(map_params=MapConfig(width=2.0, height=2.0, resolution=0.1)))
mapper.run_type = "Event"
timed = LocalMapper(component_name="timed_mapper", config=LocalMapperConfig(map_params=MapConfig(width=2.0, height=2.0, resolution=0.1)))
timed.outputs(local_map=Topic(name="/timed_map", msg_type="OccupancyGrid"))
launcher = Launcher(multi_processing=True)
launcher.kompass(components=[mapper, timed], multiprocessing=True)
launcher.bringup()
""", ["mapper", "timed_mapper"])
    scan_pub = Publisher(system.ctx, "/scan", M.LaserScan, publisher_id="test_scan")
    status = Subscriber(system.ctx, "/mapper/status", M.ComponentStatus, queue_size=50)
    timed_status = Subscriber(system.ctx, "/timed_mapper/status", M.ComponentStatus, queue_size=50)
    grid = Subscriber(system.ctx, "/local_map/occupancy_layer", M.OccupancyGrid)
    try:
        scan_pub.publish(_scan([]))
        st = wait_until(lambda: next((s for s in reversed(status.take()) if s.status == HealthLevel.SYSTEM_FAILURE), None), 10,
                        what="SYSTEM failure for an empty scan")
        assert "empty LaserScan" in st.message and "/scan" in st.src_topics
        ranges = np.full(360, 1.0)
        ranges[::3] = np.nan
        ranges[1::3] = np.inf
        ranges[5] = -np.inf
        scan_pub.publish(_scan(ranges))
        msg = wait_until(lambda: next(iter(grid.take()[-1:]), None), 10, what="a local map from a NaN/inf scan")
        g = msg.grid()
        assert g.shape == (20, 20) and (g == 100).any() and (g == 0).any()
        wait_until(lambda: any(s.status == HealthLevel.HEALTHY for s in status.take()), 30, what="healthy again")
        wait_until(lambda: any(s.status == HealthLevel.HEALTHY for s in timed_status.take()), 30, what="the timed mapper healthy")
        # The scanner goes silent: both run types report it (sensor_timeout, 1 s) instead of
        # mapping the last scan forever. A status about the empty scan may still arrive first: the
        # timed mapper's HEALTHY above can be one from before that scan reached it (a busy machine).
        for sub in (status, timed_status):
            failures: list = []

            def stale(sub=sub, failures=failures):
                failures.extend(s for s in sub.take() if s.status == HealthLevel.SYSTEM_FAILURE)
                return next((s for s in failures if "/scan is stale" in s.message), None)

            st = wait_until(stale, 10, what="SYSTEM failure for a silent scanner")
            assert "/scan" in st.src_topics, st.message
            earlier = failures[:failures.index(st)]
            assert all("empty LaserScan" in s.message for s in earlier), [s.message for s in earlier]
    finally:
        scan_pub.close(), status.close(), timed_status.close(), grid.close()
        system.stop()


@pytest.mark.parametrize("content, expect", [(None, "does not exist"), ("image: room.pgm\nresolution: [", "invalid YAML")])
def test_map_server_missing_or_malformed_file_names_it(tmp_path, content, expect):
    path = tmp_path / "bad_map.yaml"
    if content is not None:
        path.write_text(content)
    system = SystemUnderTest(tmp_path, HEADER + f"""
ms = MapServer(component_name="map_server", config=MapServerConfig(map_file_path={str(path)!r}))
launcher = Launcher(multi_processing=True)
launcher.kompass(components=[ms], multiprocessing=True)
launcher.bringup()
""", env={"PYTHONPATH": str(REPO)})
    code = system.wait_exit(timeout=60)
    assert code != 0
    out = system.output()
    assert str(path) in out and expect in out


def test_motion_server_step_test_records_csv_and_plot(tmp_path):
    folder = tmp_path / "tests"
    system = _system(tmp_path, f"""
ms = MotionServer(component_name="motion", config=MotionServerConfig(test_period=1.5, run_step_test=True, run_circle_test=False,
                  step_test_velocity=0.3, step_test_duration=0.8, tests_folder={str(folder)!r}))
ms.outputs(robot_command=Topic(name="/cmd_vel", msg_type="Twist"))  # no DriveManager here: straight to the base (default: /control)
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[FakeBase(start=(1.0, 1.0, 0.0))])
launcher.kompass(components=[ms], multiprocessing=True)
launcher.bringup()
""", ["base", "motion"])
    try:
        csv_file = wait_until(lambda: next(iter(folder.glob("*.csv")), None) if folder.exists() else None, 20, what="the step test CSV")
        wait_until(lambda: csv_file.with_suffix(".png").exists(), 10, what="the plot")
        time.sleep(0.2)
        with open(csv_file, newline="") as f:
            rows = list(csv.DictReader(f))
        assert len(rows) >= 8
        moving = [r for r in rows if float(r["t"]) < 0.7 and float(r["t"]) > 0.3]
        assert moving and all(abs(float(r["cmd_vx"]) - 0.3) < 1e-9 for r in moving)
        assert max(float(r["vx"]) for r in rows) > 0.25  # the base followed
        assert float(rows[-1]["x"]) > 1.1
    finally:
        system.stop()


def test_local_mapper_mapping_mode_publishes_memory_and_pose(tmp_path):
    from emos.transport.pubsub import Subscriber

    system = _system(tmp_path, """
mapper = LocalMapper(component_name="mapper", config=LocalMapperConfig(mapping_bounds=(-0.5, -0.5, 6.5, 4.5), map_publish_period=0.5))
mapper.run_type = "Event"
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[FakeBase(start=(1.0, 1.0, 0.3))])
launcher.kompass(components=[mapper], multiprocessing=True)
launcher.bringup()
""", ["base", "mapper"])
    memory = Subscriber(system.ctx, "/local_map/memory", M.OccupancyGrid, transient_local=True)
    pose = Subscriber(system.ctx, "/local_map/pose", M.PoseStamped)
    scans = Subscriber(system.ctx, "/scan", M.LaserScan, queue_size=500)
    try:
        grid = wait_until(lambda: next(iter(memory.take()[-1:]), None), 15, what="the obstacle memory")
        g = grid.grid()
        assert grid.header.frame_id == "map" and g.shape == (100, 140) and (g == 100).sum() > 100
        p = wait_until(lambda: next(iter(pose.take()[-1:]), None), 10, what="the localized pose")
        assert abs(p.pose.position.x - 1.0) < 0.05 and abs(p.pose.position.y - 1.0) < 0.05
        # The pose and the memory carry the stamp of the scan they were made from (a controller
        # pairs them with other data by it; a publish-time stamp would match nothing).
        # Waited for, not read after a fixed sleep: a loaded machine may not step the mapper for
        # a second. The scans are read last, so the ones the pose and the memory came from are in.
        time.sleep(1.0)
        p = wait_until(lambda: next(iter(pose.take()[-1:]), None), 30, what="a newer pose")
        grid = wait_until(lambda: next(iter(memory.take()[-1:]), None), 30, what="a newer memory")
        stamps = {(s.header.stamp.sec, s.header.stamp.nanosec) for s in scans.take()}
        assert (p.header.stamp.sec, p.header.stamp.nanosec) in stamps, (p.header.stamp, sorted(stamps)[-3:])
        assert (grid.header.stamp.sec, grid.header.stamp.nanosec) in stamps
    finally:
        memory.close(), pose.close(), scans.close()
        system.stop()


def test_a_world_frame_local_map_lies_where_the_robot_frame_one_does_from_its_scan_pose(tmp_path):
    """``local_map_frame="world"``: the same grid as the ego-centric one, published in the map
    frame at the pose of its scan, so a reader that places it by its own origin finds every
    obstacle where the ego-centric grid, read with that scan's pose, has it."""
    from emos.actors.nav.components.convert import grid_points_in_robot_frame, pose_of
    from emos.transport.pubsub import Subscriber

    system = _system(tmp_path, """
ego = LocalMapper(component_name="ego", config=LocalMapperConfig(mapping_bounds=(-0.5, -0.5, 6.5, 4.5)))
ego.run_type = "Event"
placed = LocalMapper(component_name="placed", config=LocalMapperConfig(mapping_bounds=(-0.5, -0.5, 6.5, 4.5), local_map_frame="world"))
placed.run_type = "Event"
placed.outputs(local_map=Topic(name="/placed/local_map", msg_type="OccupancyGrid"),
               mapping=Topic(name="/placed/memory", msg_type="OccupancyGrid"),
               localized_pose=Topic(name="/placed/pose", msg_type="PoseStamped"))
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[FakeBase(start=(1.0, 1.0, 0.3))])
launcher.kompass(components=[ego, placed], multiprocessing=True)
launcher.bringup()
""", ["base", "ego", "placed"])
    subs = {name: Subscriber(system.ctx, topic, M.OccupancyGrid if "map" in topic else M.PoseStamped, queue_size=200)
            for name, topic in (("ego", "/local_map/occupancy_layer"), ("placed", "/placed/local_map"), ("pose", "/placed/pose"))}
    try:
        # Each output by the stamp of its scan, gathered until one scan has all three (the three
        # arrive at their own moments: a fixed wait before one read only guessed how long that takes).
        seen: dict[str, dict] = {name: {} for name in subs}

        def one_scan_in_all():
            for name, sub in subs.items():
                seen[name].update({(m.header.stamp.sec, m.header.stamp.nanosec): m for m in sub.take()})
            return set(seen["ego"]) & set(seen["placed"]) & set(seen["pose"])

        wait_until(one_scan_in_all, 30, what="maps and a pose of one scan")
        ego, placed, poses = seen["ego"], seen["placed"], seen["pose"]
        stamp = max(set(ego) & set(placed) & set(poses))
        world_map, robot_map, pose = placed[stamp], ego[stamp], pose_of(poses[stamp])
        assert world_map.header.frame_id == "map" and robot_map.header.frame_id == "base_link"
        assert world_map.info.origin.orientation.yaw() == pytest.approx(pose[2])  # turned with the robot
        assert np.array_equal(world_map.grid(), robot_map.grid())  # the same cells
        got = grid_points_in_robot_frame(world_map, pose)
        res, o = robot_map.info.resolution, robot_map.info.origin.position
        rows, cols = np.nonzero(robot_map.grid() >= 50)
        want = np.c_[o.x + (cols + 0.5) * res, o.y + (rows + 0.5) * res]
        assert len(want) > 20 and np.allclose(np.sort(got, axis=0), np.sort(want, axis=0), atol=1e-6)
    finally:
        for sub in subs.values():
            sub.close()
        system.stop()
