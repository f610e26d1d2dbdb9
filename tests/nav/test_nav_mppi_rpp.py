"""MPPI and Regulated Pure Pursuit (Nav2's controllers): closed loop on the kinematic 2D
simulator, their bad parameters refused at definition, and both selectable like the others."""
from __future__ import annotations

import math

import numpy as np
import pytest

from emos.actors.nav.controllers import (
    MPPI,
    ControllersID,
    ControlStatus,
    MPPIConfig,
    RegulatedPurePursuit,
    RegulatedPurePursuitConfig,
    make_controller,
)
from emos.actors.nav.controllers.distance_field import DistanceField
from tests.nav.sim2d import World, make_robot, run_closed_loop, straight_path, u_turn_path

pytestmark = pytest.mark.unit

BOX = ("BOX", (0.5, 0.43, 0.3))  # a Jackal-sized rectangle: its corners sweep beyond its inscribed circle


def _mppi(robot, **kw) -> MPPI:
    return MPPI(robot, MPPIConfig(batch_size=kw.pop("batch_size", 300), **kw))


@pytest.mark.parametrize("path", [straight_path(), u_turn_path()], ids=["straight", "u-turn"])
def test_mppi_follows_a_path_to_its_goal(path):
    robot = make_robot("DIFFERENTIAL_DRIVE", *BOX)
    c = _mppi(robot)
    c.set_path(path)
    run = run_closed_loop(c, robot, World(), (0, 0, 0), max_steps=400)
    assert run.reached, run.statuses[-5:]
    # It stays with the path: no pose far from it.
    ref = np.asarray(path)
    dev = np.min(np.hypot(run.poses[:, None, 0] - ref[None, :, 0], run.poses[:, None, 1] - ref[None, :, 1]), axis=1)
    assert dev.max() < 0.25, dev.max()


@pytest.mark.parametrize("offset", [0.4, -0.35])
def test_mppi_leaves_the_path_round_an_obstacle_and_never_touches_it(offset):
    robot = make_robot("DIFFERENTIAL_DRIVE", *BOX)
    c = _mppi(robot)
    c.set_path(straight_path(5.0))
    run = run_closed_loop(c, robot, World(circles=[(2.5, offset, 0.25)]), (0, 0, 0), max_steps=400)
    assert run.reached
    assert run.min_clearance > 0.05, run.min_clearance


def test_mppi_facing_a_blocked_path_stops_short_of_the_obstacle():
    robot = make_robot("DIFFERENTIAL_DRIVE", *BOX)
    c = _mppi(robot)
    c.set_path(straight_path(5.0))
    run = run_closed_loop(c, robot, World(circles=[(2.5, 0.0, 0.3)]), (0, 0, 0), max_steps=200)
    assert not run.reached and run.min_clearance > 0.0


@pytest.mark.parametrize("kwargs, named", [
    ({"batch_size": 0}, "batch_size"), ({"time_steps": -5}, "time_steps"), ({"model_dt": 0.0}, "model_dt"),
    ({"temperature": 0.0}, "temperature"), ({"vx_min": 0.3}, "vx_min"), ({"wz_max": -1.0}, "wz_max"),
])
def test_mppi_bad_parameters_are_refused_at_definition_by_name(kwargs, named):
    with pytest.raises(ValueError, match=named):
        MPPIConfig(**kwargs)


def test_mppi_critics_are_nav2s_and_validated():
    cfg = MPPIConfig()
    assert (cfg.goal_critic.cost_weight, cfg.goal_critic.threshold_to_consider) == (5.0, 1.4)
    assert cfg.obstacles_critic.collision_margin_distance == 0.10
    with pytest.raises(ValueError, match="cost_weight"):
        cfg.path_follow_critic.cost_weight = -1.0


def test_the_distance_field_never_overestimates_a_distance():
    rng = np.random.default_rng(3)
    obs = rng.uniform(-2, 2, (40, 2))
    field = DistanceField(obs, np.array([-2.0, -2.0]), np.array([2.0, 2.0]))
    q = rng.uniform(-2, 2, (2000, 2))
    true = np.min(np.hypot(q[:, None, 0] - obs[None, :, 0], q[:, None, 1] - obs[None, :, 1]), axis=1)
    got = field(q)
    assert np.all(got <= true + 1e-6)
    assert np.all(got >= np.minimum(true, field.far) - 2 * math.sqrt(2) * field.resolution - 1e-6)


@pytest.mark.parametrize("path", [straight_path(), u_turn_path()], ids=["straight", "u-turn"])
def test_rpp_follows_a_path_to_its_goal(path):
    robot = make_robot("DIFFERENTIAL_DRIVE", *BOX)
    c = RegulatedPurePursuit(robot)
    c.set_path(path)
    run = run_closed_loop(c, robot, World(), (0, 0, 0), max_steps=400)
    assert run.reached


def test_rpp_regulates_its_speed_on_tight_arcs_near_obstacles_and_on_approach():
    robot = make_robot("DIFFERENTIAL_DRIVE", *BOX)
    c = RegulatedPurePursuit(robot, RegulatedPurePursuitConfig(use_collision_detection=False))
    c.set_path(straight_path(4.0))
    v_max = robot.ctrl_vx_limits.max_vel
    free = c._regulated_speed(0.0, np.zeros((0, 2)), np.zeros(3))
    tight = c._regulated_speed(1.0 / 0.3, np.zeros((0, 2)), np.zeros(3))  # a 0.3 m radius, under the 0.9 m minimum
    near = c._regulated_speed(0.0, np.array([[0.0, 0.55]]), np.zeros(3))  # an obstacle 0.55 m beside the centre
    assert free == pytest.approx(v_max)
    assert tight == pytest.approx(max(v_max * 0.3 / 0.9, 0.25))
    assert near < free
    c.progress.index = len(c.path) - 4  # a few centimetres from the goal
    assert c._regulated_speed(0.0, np.zeros((0, 2)), np.zeros(3)) == pytest.approx(0.05, abs=0.02)


def test_rpp_stops_instead_of_driving_into_an_obstacle_on_its_arc():
    robot = make_robot("DIFFERENTIAL_DRIVE", *BOX)
    c = RegulatedPurePursuit(robot)
    c.set_path(straight_path(5.0))
    run = run_closed_loop(c, robot, World(circles=[(2.5, 0.0, 0.25)]), (0, 0, 0), max_steps=200)
    assert not run.reached and run.min_clearance > 0.0
    assert "blocked" in run.statuses


def test_rpp_bad_parameters_are_refused_at_definition():
    with pytest.raises(ValueError, match="min_lookahead_dist"):
        RegulatedPurePursuitConfig(min_lookahead_dist=2.0, max_lookahead_dist=1.0)
    with pytest.raises(ValueError, match="desired_linear_vel"):
        RegulatedPurePursuitConfig(desired_linear_vel=-0.5)


@pytest.mark.parametrize("name, cls", [("MPPI", MPPI), ("RegulatedPurePursuit", RegulatedPurePursuit)])
def test_both_are_selectable_by_id_like_the_other_controllers(name, cls):
    robot = make_robot("DIFFERENTIAL_DRIVE")
    assert isinstance(make_controller(name, robot), cls)
    assert ControllersID.from_any(name).value == name
    c = make_controller(name, robot)
    assert c.compute(np.zeros(3), np.zeros(3)).status is ControlStatus.NO_PATH
