"""The DynaBARN-style moving-obstacle set and the Simulator's realistic options."""
import math

import numpy as np
import pytest

from emos.actors.sim.dynabarn import CORRIDOR_HALF_WIDTH, DYNABARN_COUNT, default_file, from_dynabarn, generate, load_dynabarn, to_json

pytestmark = pytest.mark.sim


def test_shipped_file_is_what_the_generator_makes():
    assert default_file().read_text() == to_json(generate())
    worlds = load_dynabarn()
    assert len(worlds) == DYNABARN_COUNT == 60
    for w in worlds.values():
        assert math.dist(w.start[:2], w.goal) == pytest.approx(20.0)
        assert w.path_length == 20.0


def test_worlds_get_harder_and_obstacles_cross_the_corridor():
    worlds = load_dynabarn()
    counts = [len(w.crossers) for w in worlds.values()]
    tops = [max(c.speed for c in w.crossers) for w in worlds.values()]
    assert counts[0] == 4 and counts[-1] == 9 and counts == sorted(counts)
    assert max(tops) <= 1.5 and min(c.speed for w in worlds.values() for c in w.crossers) >= 0.2
    assert np.mean(tops[-10:]) > np.mean(tops[:10]) + 0.5
    for w in worlds.values():
        for c in w.crossers:
            (ax, ay), (bx, by) = c.track
            assert abs(ay - by) > 2 * (CORRIDOR_HALF_WIDTH - 0.5)  # across, wall to wall
            assert min(ax, bx) > 0.5 and max(ax, bx) < 20.5  # between start and goal (slants included)


def test_a_dynabarn_world_moves_its_obstacles_in_simulated_time(make_world):
    from emos.actors.sim import SimClock

    world = from_dynabarn(59, clock=SimClock(mode="lockstep"))
    try:
        robot = world.add_robot("jackal-barn", world.spawn)
        before = [m.pose_at(0.0)[:2] for m in world.movers]
        world.step(100)
        after = [m.pose_at(world.clock.now())[:2] for m in world.movers]
        speeds = [math.dist(a, b) for a, b in zip(before, after)]
        entry = world.dynabarn
        expected = [c.speed for c in entry.crossers]
        assert all(d <= v + 1e-6 for d, v in zip(speeds, expected))  # shorter only where one turned at a wall
        assert sum(abs(d - v) < 1e-3 for d, v in zip(speeds, expected)) >= len(expected) - 2
        assert not robot.collided
        assert all(abs(p[1]) < CORRIDOR_HALF_WIDTH for p in after)
    finally:
        world.close()


def test_simulator_config_takes_the_realistic_options():
    from emos.actors.sim import SimulatorConfig
    from emos.actors.sim.component.worlds import build_setup
    from emos.actors.sim.dynamics import SkidSteerDrive
    from emos.actors.sim.sensors import WheelImuOdometry

    cfg = SimulatorConfig(world="dynabarn:3", robot="jackal-barn", odometry_mode="wheel-imu", scan_preset="jackal")
    setup = build_setup(cfg, want_scan=True, want_camera=False)
    try:
        assert isinstance(setup.robot.drive, SkidSteerDrive)
        assert isinstance(setup.odometry, WheelImuOdometry)
        assert setup.lidar.config.beams == 720 and setup.lidar.config.frame_id == cfg.frames.scan
        assert len(setup.world.movers) == len(load_dynabarn()[3].crossers)
        assert tuple(setup.robot.pose) == (0.0, 0.0, 0.0)
    finally:
        setup.world.close()
    ideal = build_setup(SimulatorConfig(world="empty", robot="jackal-barn", drive="ideal"), want_scan=False, want_camera=False)
    try:
        assert ideal.robot.drive.name == "ideal"
    finally:
        ideal.world.close()
    with pytest.raises(ValueError, match="no DynaBARN world 60"):
        SimulatorConfig(world="dynabarn:60")
    with pytest.raises(ValueError, match="SimulatorConfig.drive"):
        SimulatorConfig(drive="tank")
    with pytest.raises(ValueError, match="SimulatorConfig.odometry_mode"):
        SimulatorConfig(odometry_mode="gps")


def test_a_trial_picture_shows_the_whole_corridor():
    # A crosser can push the robot against either side wall; both must be in the picture
    # (the window once ended 1.5 m above the centre line and cut collisions near y = +2.2 off).
    from emos.tools.barn.harness import picture_bounds

    xmin, ymin, xmax, ymax = picture_bounds(load_dynabarn()[44])
    assert ymin < -CORRIDOR_HALF_WIDTH and ymax > CORRIDOR_HALF_WIDTH
    assert xmin < 0.0 and xmax > 20.0  # start and goal
    assert ymax - ymin < 2 * CORRIDOR_HALF_WIDTH + 2.0  # and not much more
