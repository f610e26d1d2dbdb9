"""A real pybullet moving-obstacle world (DynaBARN-style, realistic robot): the navigator that
tracks movers reaches the goal without a collision where the static-world navigator collides."""
import pytest

from emos.actors.sim.barn_protocol import trial_seed
from emos.actors.sim.dynabarn import load_dynabarn
from emos.tools.barn import BarnRules, run_episode
from emos.tools.barn.controllers import make_controller

pytestmark = pytest.mark.sim


def test_dynamic_navigator_passes_crossing_obstacles_that_the_static_one_runs_into():
    world = load_dynabarn()[3]
    rules = BarnRules(charge_compute=False)  # reproducible: the same trial for both navigators
    seed = trial_seed("dynabarn:3", 0)
    static = run_episode(world, make_controller("builtin-robust"), rules, seed=seed)
    assert static.collided, static
    dynamic = run_episode(world, make_controller("builtin-dynamic"), rules, seed=seed)
    assert dynamic.success and not dynamic.collided, dynamic
    assert dynamic.time_s < 15.0  # 20 m: it waits for crossers, it does not crawl


def test_the_simulator_component_counts_a_crossing_obstacle_running_into_the_robot():
    # The world the process-mode Simulator builds for dynabarn:3, the robot parked on the track
    # of its first crosser (x = 3.08 m, 0.25 m/s, now at y = -0.55 m heading to y = -2.7, back
    # after ~17 s): the flag sim_status (and so the BARN referee) reads must come up.
    from emos.actors.sim.component.config import SimulatorConfig
    from emos.actors.sim.component.worlds import build_setup

    cfg = SimulatorConfig(world="dynabarn:3", robot="jackal-barn", spawn=(3.08, 1.0, 0.0))
    setup = build_setup(cfg, want_scan=False, want_camera=False)
    try:
        assert setup.world.movers, "the moving obstacles are in the component's world"
        for _ in range(int(30.0 / setup.world.clock.dt)):
            setup.world.step()
            if setup.robot.collided:
                break
        assert setup.robot.collided
        assert 15.0 < setup.world.clock.now() < 30.0  # when the crosser comes back, not at spawn
    finally:
        setup.world.close()
