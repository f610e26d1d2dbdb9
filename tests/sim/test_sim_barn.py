import json
import subprocess
import sys

import numpy as np
import pytest

from emos.actors.sim.barn_worlds import BarnWorld, barn_metric, load_barn_worlds
from emos.tools.barn import BarnRules, run_episode, summarize

pytestmark = [pytest.mark.sim, pytest.mark.process]


class Straight:
    """Scripted navigator: drive straight ahead at a fixed speed."""

    name = "straight"
    plan = None

    def __init__(self, speed):
        self.speed = speed

    def reset(self, task):
        self.task = task

    def step(self, obs):
        return (self.speed, 0.0, 0.0)


def _empty(path_length, cylinders=()):
    return BarnWorld(idx=42, cylinders=np.asarray(cylinders, dtype=float).reshape(-1, 2), path_length=path_length)


@pytest.mark.parametrize("path_length", [1.0, 4.0, 10.0])
@pytest.mark.parametrize("ideal", [False, True])
def test_a_scripted_run_is_scored_by_the_official_formula(path_length, ideal):
    r = run_episode(_empty(path_length), Straight(1.0), BarnRules(ideal=ideal))
    # 9 m from the start (y = 3) to the goal circle (y = 12) at 1 m/s; the official clock
    # starts after the first 0.1 m (the skid-steer base gets there later, then drives the same).
    assert r.success and not r.collided and not r.timeout
    assert r.time_s == pytest.approx(8.95, abs=0.05)
    assert (r.yaw_gain is None) == ideal
    t_opt = path_length / 2.0
    assert r.metric == pytest.approx(t_opt / min(max(r.time_s, 2 * t_opt), 8 * t_opt))
    assert r.metric == pytest.approx(barn_metric(True, r.time_s, path_length))


def test_official_formula_clips_both_ways():
    assert barn_metric(True, 1.0, 10.0) == pytest.approx(0.5)  # faster than 2T still scores 0.5
    assert barn_metric(True, 100.0, 10.0) == pytest.approx(1 / 8)  # slower than 8T floors at 1/8
    assert barn_metric(True, 20.0, 10.0) == pytest.approx(0.25)
    assert barn_metric(False, 20.0, 10.0) == 0.0


def test_hitting_an_obstacle_is_a_failure_and_stops_the_run():
    r = run_episode(_empty(10.0, [[-2.25, 6.0]]), Straight(1.0))
    assert r.collided and not r.success and not r.timeout
    assert r.metric == 0.0
    assert r.time_s < 3.0  # ended at the collision, not at the time limit


def test_not_arriving_in_time_is_a_timeout():
    r = run_episode(_empty(10.0), Straight(0.0), BarnRules(time_limit=2.0))
    assert r.timeout and not r.success and not r.collided
    assert r.time_s == pytest.approx(2.0, abs=0.02)


def test_summary_rates():
    res = [run_episode(_empty(10.0), Straight(1.0)), run_episode(_empty(10.0), Straight(0.0), BarnRules(time_limit=1.0))]
    s = summarize(res, seeds=1)
    assert s == {"success_rate": 0.5, "collision_rate": 0.0, "timeout_rate": 0.5, "mean_metric": 0.25, "metric_4t": 0.125,
                 "deadline_misses": 0, "mean_time_s": pytest.approx(res[0].time_s, abs=1e-3), "seeds": 1}


def test_builtin_navigator_solves_a_real_barn_world():
    from emos.actors.nav.navigator import GridNavigator

    world = load_barn_worlds()[3]
    r = run_episode(world, GridNavigator())
    assert r.success, r.reason
    assert r.metric > 0.3


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "emos.tools.cli", "bench", "barn", *args],
                          capture_output=True, text=True, timeout=120)


def test_cli_json_output_has_exactly_the_documented_shape(tmp_path):
    path = tmp_path / "w.json"
    path.write_text(json.dumps({"5": {"cylinders": [], "path_length": 10.0},
                                "6": {"cylinders": [[-2.25, y] for y in np.arange(4.2, 6, 0.15).tolist()], "path_length": 12.0}}))
    out = _cli("--in-process", "--worlds-file", str(path), "--worlds", "5-6", "--seeds", "2", "--json", "--png",
               str(tmp_path / "png"))
    assert out.returncode == 0, out.stderr
    data = json.loads(out.stdout)  # nothing but JSON on stdout
    assert set(data) == {"worlds", "summary"}
    assert [w["idx"] for w in data["worlds"]] == [5, 5, 6, 6]  # a row per trial: world x seed
    assert set(data["worlds"][0]) == {"idx", "success", "collided", "timeout", "time_s", "metric", "seed", "metric_4t",
                                      "deadline_misses"}
    assert data["worlds"][0]["seed"] != data["worlds"][1]["seed"]
    assert set(data["summary"]) == {"success_rate", "collision_rate", "timeout_rate", "mean_metric", "metric_4t",
                                    "deadline_misses", "mean_time_s", "seeds"}
    assert data["summary"]["seeds"] == 2
    assert data["worlds"][0]["success"] is True
    assert sorted(p.name for p in (tmp_path / "png").iterdir()) == ["barn_005_s0.png", "barn_005_s1.png",
                                                                    "barn_006_s0.png", "barn_006_s1.png"]


def test_cli_ideal_and_dynabarn_options(tmp_path):
    out = _cli("--worlds", "3", "--seeds", "1", "--ideal", "--robot", "jackal-wheeled")
    assert out.returncode == 2 and "cannot go with --ideal" in out.stderr
    out = _cli("--worlds", "3", "--noisy-odometry")
    assert out.returncode == 2 and "variant of --ideal" in out.stderr
    out = _cli("--in-process", "--dynabarn", "--worlds", "2", "--seeds", "1", "--json")
    assert out.returncode == 0, out.stderr
    data = json.loads(out.stdout)
    assert [w["idx"] for w in data["worlds"]] == [2] and data["summary"]["seeds"] == 1


def test_cli_reports_a_missing_world_file_clearly(tmp_path):
    out = _cli("--worlds-file", str(tmp_path / "missing.json"))
    assert out.returncode == 2
    assert "BARN world file not found" in out.stderr


def test_navigation_core_controllers_drive_barn_through_the_adapter():
    pytest.importorskip("emos.actors.nav.controllers", reason="navigation core (emos.actors.nav) not importable")
    from emos.tools.barn.controllers import make_controller

    nav = make_controller("navcore-purepursuit")
    r = run_episode(load_barn_worlds()[3], nav)
    assert r.success, r.reason
    with pytest.raises(ValueError, match="unknown controller"):
        make_controller("teleport")


def test_every_shipped_world_keeps_a_route_through_the_navigators_soft_band():
    """The built-in navigator makes gaps narrower than half-width + lethal_bias expensive;
    with the whole map known, every shipped world must still have a route that avoids them."""
    from emos.actors.nav.mapping import HitGrid
    from emos.actors.nav.navigator import GridNavigator
    from emos.actors.nav.planning.costfield import CostField
    from emos.actors.sim.barn_worlds import BARN_GOAL, BARN_START
    from emos.actors.sim.robots import JACKAL

    band = JACKAL.width / 2 + GridNavigator().lethal_bias
    ring = 0.075 * np.c_[np.cos(np.linspace(0, 2 * np.pi, 24, endpoint=False)),
                         np.sin(np.linspace(0, 2 * np.pi, 24, endpoint=False))]
    blocked = []
    for idx, world in load_barn_worlds().items():
        grid = HitGrid((-5.25, 0.0, 0.75, 16.0), 0.05)
        grid.insert((world.cylinders[:, None, :] + ring[None]).reshape(-1, 2))
        field = CostField(grid.shape, 0.05, lethal_radius=band, inflation_radius=band + 0.45)
        (gr,), (gc,), _ = grid.cell_of(np.array([BARN_GOAL]))
        field.compute(grid.occupied, (gr, gc), grid.hit_xy, grid.origin)
        (sr,), (sc,), _ = grid.cell_of(np.array([BARN_START[:2]]))
        if not np.isfinite(field.ctg[sr, sc]):
            blocked.append(idx)
    assert blocked == []
