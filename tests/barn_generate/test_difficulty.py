"""The BARN paper's difficulty measures on hand-built grids whose values are worked out by
hand, and the shipped-against-generated comparison."""
from __future__ import annotations

import math

import numpy as np
import pytest

from emos.tools.barn import grid as G
from emos.tools.barn.difficulty import (
    characteristic_dimension,
    comparison,
    dispersion,
    ks_statistic,
    measures,
    shipped_rows,
    tortuosity,
    visibility,
)
from emos.tools.barn.generate import obstacle_distance

pytestmark = pytest.mark.unit


def corridor() -> np.ndarray:
    """7 x 7, blocked rows 0 and 6 only: the cell (3, 3) sits in the middle of a corridor
    running along the columns, open at both ends."""
    b = np.zeros((7, 7), dtype=bool)
    b[0] = b[-1] = True
    return b


def test_distance_to_the_closest_obstacle():
    d = obstacle_distance(corridor())
    assert d[3, 3] == 3.0 and d[1, 0] == 1.0 and d[0, 0] == 0.0
    b = np.zeros((5, 5), dtype=bool)
    b[0, 0] = True
    assert obstacle_distance(b)[3, 4] == pytest.approx(5.0)  # Euclidean, in cells


def test_visibility_counts_free_cells_to_the_first_obstacle_and_drops_rays_that_leave_the_grid():
    # Up and down: (3,3), (2,3), (1,3) then the wall: 3 each. The four diagonals: 3 each too.
    # Left and right run out of the grid without meeting anything: not counted.
    assert visibility(corridor(), 3, 3) == 3.0
    b = corridor()
    b[3, 5] = True  # now the ray to the right meets an obstacle after (3,3), (3,4): counted as 2
    assert visibility(b, 3, 3) == pytest.approx((6 * 3 + 2) / 7)


def test_dispersion_counts_the_changes_between_blocked_and_clear_rays_round_the_circle():
    # Radius 3: the 4 vertical and diagonal rays reach a wall (rows 0 and 6); the 2 horizontal
    # rays and the 8 rays in between (steps like (1, 2), counting 2 cells each) do not. Round
    # the circle the pattern is clear, clear, HIT, clear, HIT, clear, HIT, clear, clear, clear,
    # HIT, clear, HIT, clear, HIT, clear: 12 changes.
    assert dispersion(corridor(), 3, 3) == 12
    open_grid = np.zeros((9, 9), dtype=bool)
    assert dispersion(open_grid, 4, 4) == 0  # nothing in reach: no change


def test_characteristic_dimension_is_the_narrowest_width_through_the_cell():
    # Across the corridor: 2 cells above + 2 below = 4; along it: 3 + 3 = 6 (to the grid's
    # edges); diagonals: 2 + 2 steps of sqrt 2. The narrowest is across: 4.
    assert characteristic_dimension(corridor(), 3, 3) == 4.0
    b = corridor()
    b[2, 2] = b[4, 4] = True  # the diagonal (1, 1) now has no free cell either side
    assert characteristic_dimension(b, 3, 3) == 0.0


def test_tortuosity_is_path_length_over_the_straight_line():
    assert tortuosity(np.array([[0, 0], [0, 1], [0, 2]])) == 1.0
    assert tortuosity(np.array([[0, 0], [0, 1], [1, 2]])) == pytest.approx((1 + math.sqrt(2)) / math.sqrt(5))


def test_measures_average_over_the_path_on_the_configuration_space():
    g = np.zeros((G.ROWS, G.COLS), dtype=bool)
    g[0] = g[-1] = True  # an empty course: the robot's centre is kept 3 cells from the walls
    path = np.array([[15, c] for c in range(G.COLS)])
    m = measures(g, path)
    # configuration space: rows 0-2 and 27-29 blocked; row 15 is 12 cells from row 2 and 27
    assert m["distance"] == 12.0
    # across at the middle: 12 free rows above row 15 and 11 below; near the open ends a
    # diagonal runs out of the grid sooner and is the narrowest
    blocked = G.configuration_space(g)
    assert characteristic_dimension(blocked, 15, 15) == 23.0
    assert characteristic_dimension(blocked, 15, 0) == pytest.approx(11 * math.sqrt(2))
    assert m["characteristic_dimension"] == pytest.approx(np.mean([characteristic_dimension(blocked, 15, c) for c in range(G.COLS)]))
    assert m["characteristic_dimension"] < 23.0
    assert m["tortuosity"] == 1.0 and m["dispersion"] == 0.0
    with pytest.raises(ValueError, match="free in the configuration space"):
        measures(g, np.array([[1, 0], [1, 1]]))  # too near the wall for the robot's centre


def test_shipped_measures_skip_held_out_indices_and_compare(tmp_path):
    import json

    from emos.actors.sim.barn_worlds import default_worlds_file

    worlds = json.loads(default_worlds_file().read_text())
    subset = {k: worlds[k] for k in list(worlds)[:3]}
    subset["6"] = subset[next(iter(subset))]  # a held-out index, should a file hold one: never measured
    path = tmp_path / "w.json"
    path.write_text(json.dumps(subset))
    rows = shipped_rows(path)
    assert [r["idx"] for r in rows] == sorted(int(k) for k in subset if int(k) % 6)
    assert all(1.0 <= r["tortuosity"] < 3.0 and r["distance"] >= 1.0 for r in rows)
    table = comparison(rows, rows)
    assert {r["measure"] for r in table} >= {"distance", "visibility", "dispersion", "characteristic_dimension", "tortuosity"}
    assert all(r["ks"] == 0.0 for r in table)


def test_ks_statistic():
    assert ks_statistic([1, 2, 3], [1, 2, 3]) == 0.0
    assert ks_statistic([1, 2], [3, 4]) == 1.0


def test_set_comparison_counts_the_world_as_the_unit(tmp_path):
    from emos.tools.barn.harness import EpisodeResult
    from emos.tools.barn.setcompare import compare, rate_and_error
    from emos.tools.barn.trial_log import TrialLog, read_results

    def trial(idx: int, seed: int, ok: bool) -> EpisodeResult:
        return EpisodeResult(idx, ok, not ok, False, 5.0, 0.5 if ok else 0.0, seed=seed)

    # 4 worlds x 2 seeds: one world fails both seeds
    a = [trial(i, s, i != 3) for i in range(4) for s in range(2)]
    mean, se = rate_and_error(a, lambda t: float(t.success))
    assert mean == 0.75 and se == pytest.approx(np.std([1, 1, 1, 0], ddof=1) / 2)
    b = [trial(i, s, True) for i in range(10, 14) for s in range(2)]
    (success, collision, timeout, metric) = compare(a, b)
    assert success["difference"] == pytest.approx(-0.25) and success["within_2se"] is True  # 0.25 <= 2 x 0.25
    assert timeout["difference"] == 0.0
    # through the files, as the command reads them
    log = TrialLog(tmp_path / "a.jsonl", {"controller": "x"})
    for t in a:
        log.append(t)
    assert len(read_results(tmp_path / "a.jsonl")[1]) == 8
