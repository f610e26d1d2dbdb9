import threading
import time

import pytest

from emos.actors.sim import Lidar, LidarConfig, Odometry, OdometryConfig, SimClock

pytestmark = pytest.mark.sim


def test_lockstep_time_advances_only_with_step(make_world):
    world = make_world()
    assert world.clock.now() == 0.0
    time.sleep(0.05)
    assert world.clock.now() == 0.0
    world.step(25)
    assert world.clock.now() == pytest.approx(0.25)
    assert world.clock.stamp() == (0, 250_000_000)
    with pytest.raises(RuntimeError, match="lockstep"):
        world.start()


def test_sensors_fire_at_their_rates(make_world):
    world = make_world(ground=False)
    robot = world.add_robot("jackal")
    lidar = world.add_sensor(Lidar(robot, LidarConfig(beams=10, rate_hz=20)))
    odom = world.add_sensor(Odometry(robot, OdometryConfig(rate_hz=50)))
    counts = {"lidar": 0, "odom": 0}
    for sensor, _ in world.run_for(2.0):
        counts[sensor.name] += 1
    assert counts == {"lidar": 40, "odom": 100}
    assert odom.latest.stamp == pytest.approx(1.99)  # first reading at the first tick, then every 20 ms
    assert lidar.latest.scan_time == pytest.approx(0.05)


def test_realtime_pacing_follows_the_wall_clock(make_world):
    world = make_world(clock=SimClock(dt=0.01, mode="realtime", real_time_factor=4.0), ground=False)
    t0 = time.monotonic()
    world.run_for(0.4)
    wall = time.monotonic() - t0
    # 0.4 s simulated at 4x real time: never sooner than 0.1 s of wall time (the pacing); later
    # only by what the machine's load costs, and far from the 0.4 s of ignoring the factor.
    assert 0.1 - 0.005 <= wall < 0.35


def test_fast_mode_runs_in_the_background_and_others_wait_on_sim_time(make_world):
    world = make_world(clock=SimClock(mode="fast"), ground=False)
    done = []

    def waiter():
        rate = world.clock.rate(10.0)
        for _ in range(5):
            rate.sleep(timeout=5.0)
        done.append(world.clock.now())

    t = threading.Thread(target=waiter)
    t.start()
    world.start()
    t.join(timeout=10)
    world.stop()
    assert done and done[0] >= 0.5 - 1e-9
    stopped_at = world.clock.now()
    time.sleep(0.02)
    assert world.clock.now() == stopped_at


def test_clock_rejects_bad_values():
    with pytest.raises(ValueError, match="dt"):
        SimClock(dt=0)
    with pytest.raises(ValueError):
        SimClock(mode="warp")
