"""``emos bench barn --report FILE``: a results file summarized without running anything."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import attrs
import numpy as np
import pytest

from emos.tools.barn.harness import EpisodeResult
from emos.tools.barn.report import build_report
from tests.runtime.helpers import REPO

pytestmark = [pytest.mark.sim, pytest.mark.process]


def _write(path, trials, config=None):
    lines = [json.dumps({"config": config or {"controller": "builtin-robust"}})]
    lines += [json.dumps({"trial": attrs.asdict(t)}) for t in trials]
    path.write_text("\n".join(lines) + "\n")


def _trial(idx, seed, success=True, collided=False, timeout=False, time_s=5.0, metric=0.5, reason="goal"):
    return EpisodeResult(idx, success, collided, timeout, time_s, metric if success else 0.0, seed=seed,
                         metric_4t=metric / 2 if success else 0.0, deadline_misses=2, reason=reason)


def test_the_report_splits_tune_and_test_and_lists_failures(tmp_path):
    path = tmp_path / "r.jsonl"
    trials = [_trial(1, s) for s in (11, 12)] + [_trial(5, 21), _trial(5, 22, success=False, collided=True,
                                                                          reason="collision at (1.00, 2.00)")]
    trials += [_trial(7, 31, success=False, timeout=True, reason="time limit")]  # world 7: one seed of two so far
    _write(path, trials)
    with open(path, "a") as f:
        f.write('{"trial": {"idx": 9, "succ')  # a line cut short by a crash: left out, said on stderr
    report = build_report(path)
    assert (report["trials"], report["worlds"], report["seeds"], report["complete_worlds"]) == (5, 3, 2, 2)
    tune, test = report["splits"]["tune"], report["splits"]["test"]
    assert (tune["worlds"], tune["trials"], test["worlds"], test["trials"]) == (2, 3, 1, 2)
    assert tune["success_rate"] == round(2 / 3, 4) and tune["timeout_rate"] == round(1 / 3, 4)
    assert test["success_rate"] == 0.5 and test["collision_rate"] == 0.5
    assert report["splits"]["all"]["success_rate"] == 0.6
    assert report["failures"] == [{"idx": 5, "seed": 22, "reason": "collision at (1.00, 2.00)"},
                                  {"idx": 7, "seed": 31, "reason": "time limit"}]


def test_the_cli_prints_the_report_and_refuses_a_file_that_is_not_one(tmp_path):
    path = tmp_path / "r.jsonl"
    _write(path, [_trial(5, 1), _trial(10, 2, success=False, collided=True, reason="collision at (0.10, 0.20)")])
    env = dict(os.environ, PYTHONPATH=str(REPO))
    out = subprocess.run([sys.executable, "-m", "emos", "bench", "barn", "--report", str(path)], capture_output=True,
                         text=True, timeout=60, env=env)
    assert out.returncode == 0, out.stderr
    assert "2 trials, 2 worlds" in out.stdout and "world 10 seed 2: collision at (0.10, 0.20)" in out.stdout
    assert " test " in out.stdout and " tune " not in out.stdout  # both worlds are idx % 5 == 0
    bad = tmp_path / "bad.jsonl"
    bad.write_text("hello\n")
    out = subprocess.run([sys.executable, "-m", "emos", "bench", "barn", "--report", str(bad)], capture_output=True,
                         text=True, timeout=60, env=env)
    assert out.returncode == 2 and "not a results file of emos bench barn" in out.stderr


def test_a_file_with_no_finished_trial_says_so_and_names_what_a_bad_line_lacks(tmp_path):
    path = tmp_path / "r.jsonl"
    _write(path, [])
    with open(path, "a") as f:
        f.write(json.dumps({"trial": {"idx": 3, "seed": 4}}) + "\n")  # a trial without its outcome
    env = dict(os.environ, PYTHONPATH=str(REPO))
    out = subprocess.run([sys.executable, "-m", "emos", "bench", "barn", "--report", str(path)], capture_output=True,
                         text=True, timeout=60, env=env)
    assert out.returncode == 0, out.stderr
    assert "no finished trial yet" in out.stdout and "split" not in out.stdout  # no empty table
    assert "line 2 unreadable" in out.stderr and "'success'" in out.stderr  # names the missing field


def test_two_files_are_compared_on_the_pairs_both_hold(tmp_path):
    new, old = tmp_path / "new.jsonl", tmp_path / "old.jsonl"
    failed = dict(success=False, collided=True, reason="collision at (0.00, 1.00)")
    _write(new, [_trial(1, 11), _trial(1, 12), _trial(2, 21, **failed), _trial(5, 51), _trial(9, 91)])  # 9: only here
    _write(old, [_trial(1, 11, **failed), _trial(1, 12), _trial(2, 21), _trial(5, 51, **failed), _trial(3, 31)],
           config={"controller": "builtin-robust", "code": "before"})
    from emos.tools.barn.report import build_comparison

    got = build_comparison(new, old)
    assert got["pairs"] == 4 and got["config_differs_in"] == ["code"]
    assert got["report"]["splits"]["all"]["success_rate"] == 0.75 and got["against"]["splits"]["all"]["success_rate"] == 0.5
    assert got["report"]["splits"]["test"]["trials"] == 1 and got["against"]["splits"]["test"]["success_rate"] == 0.0
    assert got["changed_worlds"] == [{"idx": 1, "fixed": 1, "broken": 0}, {"idx": 2, "fixed": 0, "broken": 1},
                                     {"idx": 5, "fixed": 1, "broken": 0}]
    env = dict(os.environ, PYTHONPATH=str(REPO))
    cli = [sys.executable, "-m", "emos", "bench", "barn"]
    out = subprocess.run([*cli, "--report", str(new), "--against", str(old)], capture_output=True, text=True, timeout=60, env=env)
    assert out.returncode == 0, out.stderr
    assert "4 world-seed pairs in both files; their configurations differ in: code" in out.stdout
    assert "world 2: 0 seed(s) succeed only in new.jsonl, 1 only in old.jsonl" in out.stdout
    out = subprocess.run([*cli, "--against", str(old)], capture_output=True, text=True, timeout=60, env=env)
    assert out.returncode != 0 and "give both" in out.stderr


def test_the_outcome_grid_has_a_column_per_world_and_a_row_per_seed():
    from emos.tools.barn import report_plot as rp

    trials = [_trial(5, 52, success=False, collided=True), _trial(5, 51, time_s=30.0, metric=0.3),
              _trial(1, 11), _trial(1, 12, success=False, timeout=True), _trial(7, 71)]
    worlds, grid = rp.outcome_grid(trials)
    assert worlds == [1, 5, 7] and grid.shape == (2, 3)
    assert grid[:, 0].tolist() == [rp.SUCCESS, rp.TIMEOUT]
    assert grid[:, 1].tolist() == [rp.SLOW_SUCCESS, rp.COLLISION]  # seeds in order: 51 before 52
    assert grid[:, 2].tolist() == [rp.SUCCESS, rp.NOT_RUN]  # world 7 has one seed so far
    worlds, grid = rp.outcome_grid(trials, worlds=[1, 3])  # fixed columns: a world without trials is not run
    assert grid[:, 1].tolist() == [rp.NOT_RUN, rp.NOT_RUN]


def test_the_cli_draws_the_outcome_map_and_a_collision_shows_in_red(tmp_path):
    from PIL import Image

    from emos.tools.barn.report_plot import COLLISION, COLOURS

    red = np.round(COLOURS[COLLISION] * 255).astype(int)

    def reds(picture):
        pixels = np.asarray(Image.open(picture).convert("RGB")).astype(int)
        return int((np.abs(pixels - red).max(axis=2) <= 3).sum())

    clean, crashed = tmp_path / "clean.jsonl", tmp_path / "crashed.jsonl"
    _write(clean, [_trial(i, s) for i in (1, 2, 3) for s in (1, 2)])
    _write(crashed, [_trial(i, s, **(dict(success=False, collided=True) if (i, s) == (2, 2) else {}))
                     for i in (1, 2, 3) for s in (1, 2)])
    env = dict(os.environ, PYTHONPATH=str(REPO))
    cli = [sys.executable, "-m", "emos", "bench", "barn"]
    for path in (clean, crashed):
        out = subprocess.run([*cli, "--report", str(path), "--plot", str(path.with_suffix(".png"))],
                             capture_output=True, text=True, timeout=60, env=env)
        assert out.returncode == 0 and "outcome map written" in out.stderr, out.stderr
        assert "3 worlds" in out.stdout  # the report is printed as without --plot
    # Both have the legend's red swatch; only the run with a collision has a red cell (a sixth of
    # a 2-seed band's height by a fiftieth of its width: hundreds of pixels).
    assert reds(crashed.with_suffix(".png")) - reds(clean.with_suffix(".png")) > 200
    both = tmp_path / "both.png"
    out = subprocess.run([*cli, "--report", str(crashed), "--against", str(clean), "--plot", str(both)],
                         capture_output=True, text=True, timeout=60, env=env)
    assert out.returncode == 0 and both.exists(), out.stderr
    out = subprocess.run([*cli, "--report", str(clean), "--plot", str(tmp_path / "map.txt")],
                         capture_output=True, text=True, timeout=60, env=env)
    assert out.returncode != 0 and ".png, .svg or .pdf" in out.stderr


def test_a_run_s_progress_estimates_the_time_left_from_the_trials_it_ran_itself():
    import time

    from emos.tools.barn import _time_left

    trials = {(idx, k): None for idx in (1, 2, 3) for k in (0, 1)}
    resumed = {(1, 0), (1, 1), (3, 1)}  # read back from the results file: free
    started = time.perf_counter() - 120.0
    # Worlds 1 and 2 done: 2 trials ran in 120 s, 1 of the remaining 2 still has to run.
    assert _time_left(trials, resumed, 4, started) == ", about 1 min left"
    assert _time_left(trials, resumed, 2, started) == ""  # nothing ran yet: no pace to go by
    assert _time_left(trials, resumed, 6, started) == ""  # all done
