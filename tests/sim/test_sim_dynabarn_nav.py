"""A real pybullet moving-obstacle world (DynaBARN-style, realistic robot): the navigator that
tracks movers reaches the goal without a collision where the static-world navigator collides."""
from emos.actors.sim.barn import BarnRules, run_episode
from emos.actors.sim.barn.controllers import make_controller
from emos.actors.sim.barn_protocol import trial_seed
from emos.actors.sim.dynabarn import load_dynabarn


def test_dynamic_navigator_passes_crossing_obstacles_that_the_static_one_runs_into():
    world = load_dynabarn()[3]
    rules = BarnRules(charge_compute=False)  # reproducible: the same trial for both navigators
    seed = trial_seed("dynabarn:3", 0)
    static = run_episode(world, make_controller("builtin-robust"), rules, seed=seed)
    assert static.collided, static
    dynamic = run_episode(world, make_controller("builtin-dynamic"), rules, seed=seed)
    assert dynamic.success and not dynamic.collided, dynamic
    assert dynamic.time_s < 15.0  # 20 m: it waits for crossers, it does not crawl
