"""Planner ids, planner parameters and OMPLConfig validation."""

import numpy as np
import pytest

from emos.actors.nav.planning import (
    SPEC_PLANNERS,
    OMPLConfig,
    PlannerNotAvailableError,
    UnknownPlannerError,
    available_planners,
    interpolate_se2,
    make_planner,
    path_length,
    resolve_planner_name,
)

pytestmark = pytest.mark.unit

DESIGN_LIST = {"RRT", "RRTConnect", "RRTstar", "InformedRRTstar", "SORRTstar", "AORRTC", "PRM", "PRMstar",
               "FMT", "BFMT", "BITstar", "KPIECE1", "BKPIECE1", "LBKPIECE1"}


@pytest.fixture()
def si():
    from ompl import base as ob

    space = ob.SE2StateSpace()
    bounds = ob.RealVectorBounds(2)
    bounds.setLow(0.0)
    bounds.setHigh(1.0)
    space.setBounds(bounds)
    info = ob.SpaceInformation(space)
    info.setStateValidityChecker(lambda state: True)
    info.setup()
    return info


def test_every_binding_planner_is_available():
    assert set(available_planners()) == DESIGN_LIST


@pytest.mark.parametrize("given", ["ompl.geometric.RRTConnect", "geometric.RRTConnect", "RRTConnect", "rrtconnect"])
def test_planner_id_forms(given):
    assert resolve_planner_name(given) == "RRTConnect"


def test_spec_planner_missing_from_binding_says_so_and_lists_available():
    missing = sorted(set(SPEC_PLANNERS) - DESIGN_LIST)
    assert "SST" in missing and "LazyPRM" in missing
    for name in missing:
        with pytest.raises(PlannerNotAvailableError) as err:
            resolve_planner_name(f"ompl.geometric.{name}")
        assert "does not expose" in str(err.value)
        assert "RRTConnect" in str(err.value) and "KPIECE1" in str(err.value)


def test_unknown_planner_lists_available():
    with pytest.raises(UnknownPlannerError) as err:
        OMPLConfig(planner_id="ompl.geometric.Teleport")
    assert "unknown planner" in str(err.value)
    assert all(name in str(err.value) for name in DESIGN_LIST)


def test_parameters_reach_the_ompl_planner(si):
    p = make_planner("RRTstar", si, {"range": 0.7, "goal_bias": 0.2, "rewire_factor": 1.3, "use_k_nearest": False})
    assert (p.getRange(), p.getGoalBias(), p.getRewireFactor(), p.getKNearest()) == (0.7, 0.2, 1.3, False)
    k = make_planner("KPIECE1", si, {"border_fraction": 0.5, "goal_bias": "0" if False else 0.1})
    assert (k.getBorderFraction(), k.getGoalBias()) == (0.5, 0.1)
    f = make_planner("FMT", si, {"num_samples": 500, "use_k_nearest": "false"})
    assert (f.getNumSamples(), f.getNearestK()) == (500, False)
    b = make_planner("BITstar", si, {"samples_per_batch": 50, "use_graph_pruning": False})
    assert (b.getSamplesPerBatch(), b.getPruning()) == (50, False)
    prm = make_planner("PRM", si, {"max_nearest_neighbors": 12})
    assert prm.getMaxNearestNeighbors() == 12


def test_bad_parameters_fail_before_the_planner_is_built(si):
    # OMPL 2.0.1's AORRTC crashes the process if destroyed before setup(); a bad parameter
    # must therefore raise before construction (a crash here would kill the test run).
    with pytest.raises(ValueError, match="unknown parameter"):
        make_planner("AORRTC", si, {"goal_bias": 0.1})
    p = make_planner("AORRTC", si, {"range": 0.4})
    assert p.getRange() == 0.4
    p.setup()  # leave it in a state it can be destroyed from


def test_unknown_or_badly_typed_parameters_are_clear_errors():
    with pytest.raises(ValueError) as err:
        OMPLConfig(planner_id="RRTConnect", planner_params={"goal_bias": 0.1})
    assert "unknown parameter 'goal_bias'" in str(err.value)
    assert "intermediate_states" in str(err.value) and "range" in str(err.value)
    with pytest.raises(ValueError, match="no setter"):
        OMPLConfig(planner_id="BFMT", planner_params={"balanced": True})
    with pytest.raises(TypeError, match="boolean"):
        OMPLConfig(planner_id="RRT", planner_params={"intermediate_states": "maybe"})
    with pytest.raises(ValueError, match="fraction"):
        OMPLConfig(planner_id="RRT", planner_params={"goal_bias": 1.5})
    with pytest.raises(TypeError, match="integer"):
        OMPLConfig(planner_id="FMT", planner_params={"num_samples": 10.5})
    with pytest.raises(ValueError, match="none"):
        OMPLConfig(planner_id="PRMstar", planner_params={"range": 1.0})


def test_config_defaults_follow_the_spec():
    cfg = OMPLConfig()
    assert (cfg.log_level, cfg.planning_timeout, cfg.simplification_timeout, cfg.goal_tolerance) == ("WARN", 10.0, 0.01, 0.01)
    assert cfg.optimization_objective == "PathLengthOptimizationObjective"
    assert cfg.planner_id == "ompl.geometric.KPIECE1" and cfg.planner_name == "KPIECE1"


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"planning_timeout": 0}, "planning_timeout"),
        ({"goal_tolerance": -1}, "goal_tolerance"),
        ({"simplification_timeout": float("inf")}, "simplification_timeout"),
        ({"log_level": "LOUD"}, "log_level"),
        ({"optimization_objective": "MaximizeMinClearanceObjective"}, "not available through the installed"),
        ({"optimization_objective": "Shortest"}, "unknown objective"),
        ({"occupied_threshold": 101}, "occupied_threshold"),
        ({"path_resolution": 0}, "path_resolution"),
    ],
)
def test_config_rejects_bad_values(kwargs, message):
    with pytest.raises(ValueError, match=message):
        OMPLConfig(**kwargs)


def test_config_validates_on_assignment():
    cfg = OMPLConfig()
    with pytest.raises(ValueError, match="planning_timeout"):
        cfg.planning_timeout = -2.0


def test_interpolation_spacing_endpoints_and_shortest_yaw():
    path = np.array([[0.0, 0.0, 3.0], [1.0, 0.0, -3.0], [1.0, 0.33, -3.0]])
    out = interpolate_se2(path, 0.1)
    steps = np.hypot(*np.diff(out[:, :2], axis=0).T)
    assert steps.max() <= 0.1 + 1e-12
    assert np.allclose(out[0], path[0]) and np.allclose(out[-1], path[-1])
    # Every original pose is kept.
    assert any(np.allclose(row, path[1]) for row in out)
    # 3.0 -> -3.0 turns through pi (0.28 rad), not through 0 (6 rad).
    first_leg = out[: 11]
    yaw_jumps = np.abs((np.diff(first_leg[:, 2]) + np.pi) % (2 * np.pi) - np.pi)
    assert yaw_jumps.sum() == pytest.approx(2 * np.pi - 6.0)
    assert path_length(out) == pytest.approx(1.33)
    fine_turn = interpolate_se2(np.array([[0, 0, 0.0], [0, 0, 1.0]]), 0.1, max_yaw_step=0.1)
    assert len(fine_turn) == 11
    with pytest.raises(ValueError):
        interpolate_se2(np.zeros((3, 2)), 0.1)


def test_config_from_the_spec_yaml_block():
    import yaml

    block = yaml.safe_load(
        """
ompl:
  log_level: 'WARN'
  planning_timeout: 10.0
  simplification_timeout: 0.01
  goal_tolerance: 0.01
  optimization_objective: 'PathLengthOptimizationObjective'
  planner_id: 'ompl.geometric.KPIECE1'
  planner_params: {range: 0.5, border_fraction: 0.8}
"""
    )["ompl"]
    cfg = OMPLConfig.from_dict(block)
    assert cfg.planner_name == "KPIECE1" and cfg.planner_params == {"range": 0.5, "border_fraction": 0.8}
    with pytest.raises(ValueError, match="unknown key.*planing_timeout"):
        OMPLConfig.from_dict({"planing_timeout": 1.0})
