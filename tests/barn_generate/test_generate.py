"""The BARN world generator (issue 38 item 2): the cellular automaton, the guaranteed path,
determinism, and the official worlds' geometry."""
from __future__ import annotations

import argparse
import json

import numpy as np
import pytest

from emos.actors.sim.barn_worlds import BARN_CYLINDER_RADIUS, load_barn_worlds
from emos.tools.barn import grid as G
from emos.tools.barn.generate import (
    GeneratorConfig,
    apply_generate,
    astar,
    generate_world,
    generate_worlds,
    guaranteed_path,
    parameter_set,
    region,
    smooth,
    write_worlds_file,
)

pytestmark = pytest.mark.unit


def test_the_same_seed_gives_the_same_worlds_and_world_i_does_not_depend_on_the_count():
    a = generate_worlds(6, seed=11)
    b = generate_worlds(3, seed=11)
    for x, y in zip(a, b):
        assert np.array_equal(x.grid, y.grid) and np.array_equal(x.path, y.path)
        assert (x.fill, x.smoothing, x.path_length) == (y.fill, y.smoothing, y.path_length)
    other = generate_worlds(3, seed=12)
    assert not all(np.array_equal(x.grid, y.grid) for x, y in zip(b, other))  # another seed, other worlds


def test_worlds_are_spread_evenly_over_the_parameter_sets():
    config = GeneratorConfig()
    sets = [parameter_set(3, i, config) for i in range(24)]  # two runs of the 12 sets
    assert sorted(sets[:12]) == sorted(sets[12:]) == sorted((f, s) for f in config.fills for s in config.smoothing)
    assert sets[:12] != sets[12:]  # shuffled per run, not in a fixed order


def test_every_generated_world_has_a_path_from_the_entry_to_the_exit_column():
    for w in generate_worlds(6, seed=5):
        blocked = G.configuration_space(w.grid)
        p = w.path
        assert p[0][1] == 0 and p[-1][1] == G.COLS - 1
        assert not blocked[p[:, 0], p[:, 1]].any()  # every cell of it free for the robot's centre
        steps = np.diff(p, axis=0)
        assert (np.abs(steps).max(axis=1) == 1).all()  # 8-connected moves
        headings = np.arctan2(steps[:, 0], steps[:, 1])
        turns = np.abs((np.diff(headings) + np.pi) % (2 * np.pi) - np.pi)
        assert (turns <= np.pi / 4 + 1e-9).all()  # at most 45 degrees per step
        # the side walls are the grid's first and last rows
        assert w.grid[0].all() and w.grid[-1].all()
        assert 10.0 < w.path_length < 16.0


def test_a_world_without_a_path_is_rejected():
    g = np.zeros((G.ROWS, G.COLS), dtype=bool)
    g[0] = g[-1] = True
    g[:, 15] = True  # a wall across the course
    rng = np.random.default_rng(0)
    assert guaranteed_path(g, rng) is None
    blocked = G.configuration_space(g)
    assert astar(blocked, (15, 0), (15, G.COLS - 1)) is None
    g[13:17, 15] = False  # 4 cells: too narrow for the robot's 5 x 5 cells
    assert guaranteed_path(g, rng) is None
    g[10:20, 15] = False  # a gap it fits through
    path = guaranteed_path(g, rng)
    assert path is not None and set(path[:, 1]) == set(range(G.COLS))


def test_astar_takes_the_straight_line_on_an_open_grid_and_never_squeezes_between_diagonals():
    blocked = np.zeros((9, 9), dtype=bool)
    path = astar(blocked, (4, 0), (4, 8))
    assert path.tolist() == [[4, c] for c in range(9)]
    blocked = np.ones((3, 3), dtype=bool)
    blocked[0, 0] = blocked[1, 1] = False  # only a diagonal step joins them, between two blocked cells
    assert astar(blocked, (0, 0), (1, 1)) is None
    blocked[0, 1] = False  # one side open: the diagonal step is allowed
    assert astar(blocked, (0, 0), (1, 1)).tolist() == [[0, 0], [1, 1]]


def test_smoothing_fills_crowded_cells_and_empties_lonely_ones():
    g = np.zeros((7, 7), dtype=bool)
    g[0] = g[-1] = True
    g[3, 5] = True  # alone: no filled neighbour -> emptied
    g[2, 1] = g[2, 2] = g[3, 1] = g[4, 1] = g[4, 2] = True  # (3, 2) has 5 filled neighbours -> filled
    out = smooth(g)
    assert not out[3, 5] and out[3, 2]
    # beyond the side walls counts as filled: a row-1 cell with the wall above and 2 filled
    # cells beside it has 5 filled neighbours
    h = np.zeros((7, 7), dtype=bool)
    h[0] = h[-1] = True
    h[1, 2] = h[1, 4] = True
    assert smooth(h)[1, 3]
    # beyond the open ends counts as free: the same at column 0 gets only 3 + 1
    k = np.zeros((7, 7), dtype=bool)
    k[0] = k[-1] = True
    k[1, 1] = True
    assert not smooth(k)[1, 0]


def test_region_is_four_connected():
    free = np.array([[1, 0], [0, 1]], dtype=bool)
    assert region(free, (0, 0)).sum() == 1  # the diagonal neighbour is not joined


def test_shipped_worlds_round_trip_through_the_grid():
    """Every shipped world's cylinders are exactly the generator's output for its grid: the
    generated worlds have the official geometry (containment posts, cylinder places)."""
    for idx, world in load_barn_worlds().items():
        g = G.cylinders_to_grid(world.cylinders)
        back = G.grid_to_cylinders(g)
        assert len(back) == len(world.cylinders), idx
        assert set(map(tuple, np.round(back, 4))) == set(map(tuple, np.round(world.cylinders, 4))), idx


def test_a_generated_world_file_loads_through_the_barn_loader(tmp_path):
    path = write_worlds_file(tmp_path / "g.json", 4, seed=9)
    worlds = load_barn_worlds(path)
    assert sorted(worlds) == [0, 1, 2, 3]
    for idx, w in worlds.items():
        gen = generate_world(9, idx)
        assert np.allclose(w.cylinders, gen.cylinders) and w.path_length == pytest.approx(gen.path_length, abs=1e-4)
        # the containment posts: 30 across the back, 33 on each side, as in every official world
        assert np.sum(np.isclose(w.cylinders[:, 1], BARN_CYLINDER_RADIUS)) >= 30
    extra = json.loads(path.read_text())["0"]["generated"]
    assert extra["seed"] == 9 and extra["fill"] in GeneratorConfig().fills


def test_generate_option_replaces_the_world_source(tmp_path):
    from emos.tools.barn import _load, add_arguments

    parser = argparse.ArgumentParser()
    add_arguments(parser)  # `emos bench barn`'s own parser: --generate is among its options
    args = parser.parse_args(["--generate", "3", "--seed", "21", "--generated-dir", str(tmp_path)])
    apply_generate(args)
    worlds, indices = _load(args)
    assert indices == [0, 1, 2] and args.worlds_file.parent == tmp_path
    assert np.allclose(worlds[2].cylinders, generate_world(21, 2).cylinders)
    for bad in (["--generate", "3", "--split", "tune"], ["--generate", "0"],
                ["--generate", "2", "--worlds-file", str(tmp_path / "x.json")]):
        args = parser.parse_args([*bad, "--generated-dir", str(tmp_path)])
        with pytest.raises(ValueError, match="--generate|--split"):
            apply_generate(args)


def test_bad_generator_parameters_are_named():
    with pytest.raises(ValueError, match="fills"):
        GeneratorConfig(fills=(1.5,))
    with pytest.raises(ValueError, match="smoothing"):
        GeneratorConfig(smoothing=(-1,))
    with pytest.raises(ValueError, match="no world with a path"):
        generate_world(0, 0, GeneratorConfig(fills=(0.95,), smoothing=(0,)), max_attempts=20)
