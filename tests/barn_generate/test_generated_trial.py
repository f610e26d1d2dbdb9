"""End to end: a generated world runs through ``emos bench barn`` as a shipped world does (the
world file, the Simulator's loader, the navigation components as processes, the referee)."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from emos.tools.barn.generate import generate_world, parameter_set
from tests.runtime.helpers import REPO

pytestmark = [pytest.mark.sim, pytest.mark.process]

SEED = 0  # world 0 of seed 0 is of the sparsest parameter set (fill 0.15): the stack drives it


def test_a_generated_world_runs_through_the_supervised_processes(tmp_path):
    assert parameter_set(SEED, 0)[0] == 0.15
    env = dict(os.environ, PYTHONPATH=str(REPO))
    made = subprocess.run([sys.executable, "-m", "emos.tools.barn.generate", "--count", "1", "--seed", str(SEED),
                           "--out", str(tmp_path / "generated.json")], cwd=REPO, capture_output=True, text=True,
                          timeout=120, env=env)
    assert made.returncode == 0, made.stderr[-2000:]
    worlds_file = made.stdout.strip()
    out = subprocess.run([sys.executable, "-m", "emos", "bench", "barn", "--worlds-file", worlds_file, "--seeds", "1",
                          "--seed", str(SEED), "--json", "--results", str(tmp_path / "trials.jsonl")],
                         cwd=REPO, capture_output=True, text=True, timeout=240, env=env)
    assert out.returncode == 0, out.stderr[-3000:]
    result = json.loads(out.stdout)
    (trial,) = result["worlds"]
    assert trial["idx"] == 0 and trial["success"], out.stderr[-3000:]
    # scored against the generated world's own reference path (the metric's optimal time)
    optimal = generate_world(SEED, 0).path_length / 2.0
    assert trial["metric"] == pytest.approx(optimal / max(trial["time_s"], 2 * optimal), abs=2e-3)
    header = json.loads((tmp_path / "trials.jsonl").read_text().splitlines()[0])
    assert header["config"]["worlds"] == str((tmp_path / "generated.json").resolve())  # the run names its world file
