"""``emos bench slam --peer karto``: OpenKarto (slam_toolbox's SLAM) on the same scans and odometry,
from the benchmark-only environment; its bad inputs and an unreachable registry are clear errors."""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from emos.tools.bench import peer_env
from tests.bench_peers import unreachable_registry_env

pytest.importorskip("gtsam")
pytestmark = pytest.mark.process

OREBRO = Path(__file__).parent / "data" / "orebro-corrected.log.gz"
PEER_SCRIPT = Path(peer_env.__file__).with_name("slam_peer_karto.py")

needs_karto = pytest.mark.skipif(
    not peer_env.peer_env_has("yag_slam"),
    reason=f"the karto peer environment ({peer_env.peer_dir()}) is not installed; `emos bench slam --peer karto` "
           "creates it from the package registry, which this test does not reach")


def _args(**over: object) -> argparse.Namespace:
    base = {"log": str(OREBRO), "seed": 0, "json": True, "noise": None, "max_range": 30.0, "scans": 110, "map": None,
            "plot": None, "reference": None, "quiet": True, "param": [], "peer": "karto"}
    return argparse.Namespace(**{**base, **over})


@needs_karto
def test_karto_maps_the_same_scans_from_the_same_odometry_and_is_scored_alike(tmp_path: Path) -> None:
    from emos.tools.bench.slam import measure

    result = measure(_args(plot=str(tmp_path / "both.png")))
    (peer,) = result["peers"]
    assert peer["slam"] == "karto" and "slam_toolbox" in peer["about"]
    # It did SLAM on that odometry: far better than the odometry alone (which is metres off).
    assert result["odometry_ate_rmse_m"] > 1.0
    assert 0.0 < peer["ate_rmse_m"] < 0.5 * result["odometry_ate_rmse_m"], peer
    assert 0.0 < peer["rpe_1m_rmse_m"] < 0.5 and peer["cpu_s_per_scan"] > 0
    assert isinstance(peer["loop_closures"], int)
    assert (tmp_path / "both.png").stat().st_size > 10_000  # the map with both trajectories, and the error panel


def _run_peer(tmp_path: Path, ranges: np.ndarray, angles: np.ndarray, odom: np.ndarray) -> subprocess.CompletedProcess[str]:
    given, got = tmp_path / "in.npz", tmp_path / "out.npz"
    np.savez(given, ranges=ranges, angles=angles, odom=odom, max_range=30.0)
    return subprocess.run([str(peer_env.peer_python()), str(PEER_SCRIPT), "--input", str(given), "--output", str(got)],
                          capture_output=True, text=True, timeout=300)


def _round_room(poses: np.ndarray, angles: np.ndarray, radius: float = 6.0) -> np.ndarray:
    """Ranges from each pose to the wall of a round room around the origin, with a pillar-free view."""
    out = []
    for x, y, th in poses:
        d = np.column_stack([np.cos(th + angles), np.sin(th + angles)])
        b = d @ np.array([x, y])
        out.append(-b + np.sqrt(b * b - (x * x + y * y - radius * radius)))
    return np.array(out)


@needs_karto
def test_the_peer_reads_nan_inf_and_max_range_as_no_echo_and_refuses_mismatched_inputs(tmp_path: Path) -> None:
    """NaN, inf and readings at or past the benchmark's max range are "no echo" for Karto too: the
    same poses as those beams far out of range; arrays that do not fit are refused by name."""
    angles = np.linspace(-np.pi / 2, np.pi / 2, 181)
    odom = np.array([[0.0, 0.0, 0.0], [0.5, 0.1, 0.05], [1.0, 0.2, 0.1], [1.4, 0.5, 0.3]])
    ranges = _round_room(odom, angles)
    bad = np.zeros_like(ranges, dtype=bool)
    bad[:, ::5] = True
    odd = ranges.copy()
    odd[bad] = np.resize(np.array([np.nan, np.inf, 30.0, 45.0]), int(bad.sum()))
    far = ranges.copy()
    far[bad] = 1000.0
    results = []
    for r in (odd, far):
        done = _run_peer(tmp_path, r, angles, odom)
        assert done.returncode == 0, done.stderr
        assert json.loads(done.stdout.strip().splitlines()[-1])["loop_closures"] == 0
        results.append(np.load(tmp_path / "out.npz")["est"])
    assert results[0].shape == (4, 3) and np.all(np.isfinite(results[0]))
    np.testing.assert_array_equal(results[0], results[1])

    done = _run_peer(tmp_path, ranges[:, :100], angles, odom)
    assert done.returncode != 0 and "expected ranges (n, beams), angles (beams,) and odom (n, 3)" in done.stderr


def test_an_unreachable_registry_is_a_clear_error(tmp_path: Path) -> None:
    env = unreachable_registry_env(tmp_path)
    done = subprocess.run([sys.executable, "-m", "emos", "bench", "slam", "--log", str(OREBRO), "--scans", "5",
                           "--peer", "karto", "--json", "--quiet"], capture_output=True, text=True, env=env, timeout=600)
    assert done.returncode == 2, done.stderr
    assert "peer karto: cannot install yag-slam==0.3.0" in done.stderr and "registry" in done.stderr
    assert "Traceback" not in done.stderr
