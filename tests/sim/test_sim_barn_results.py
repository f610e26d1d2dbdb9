"""``emos bench barn --results FILE``: trials are appended as they finish, a second run resumes
from the file instead of running them again, and a file of another configuration is refused."""
import json
import subprocess
import sys

import pytest

pytestmark = pytest.mark.process

ARGS = ["--in-process", "--ideal", "--worlds", "5,10", "--seeds", "1", "--json"]


def _bench(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "emos", "bench", "barn", *args], capture_output=True, text=True, timeout=600)


def test_a_run_resumes_from_its_results_file_and_refuses_another_configuration(tmp_path):
    results = tmp_path / "barn.jsonl"
    first = _bench(*ARGS, "--results", str(results))
    assert first.returncode == 0, first.stderr
    lines = results.read_text().splitlines()
    assert len(lines) == 3 and json.loads(lines[0])["config"]["controller"] == "builtin-robust"
    assert sorted(json.loads(line)["trial"]["idx"] for line in lines[1:]) == [5, 10]

    # A crash mid-write leaves half a line: that trial (world 10's) runs again, world 5's does not.
    results.write_text("\n".join(lines[:2]) + "\n" + lines[2][: len(lines[2]) // 2] + "\n")
    again = _bench(*ARGS, "--results", str(results))
    assert again.returncode == 0, again.stderr
    assert "line 3 unreadable" in again.stderr
    assert json.loads(again.stdout)["summary"] == json.loads(first.stdout)["summary"]  # ideal runs are deterministic
    rows = [json.loads(line) for line in results.read_text().splitlines()[1:] if line.endswith("}")]
    assert sorted(r["trial"]["idx"] for r in rows if "trial" in r) == [5, 10]

    other = _bench(*ARGS, "--controller", "builtin", "--results", str(results))
    assert other.returncode == 2
    assert "another configuration" in other.stderr and "controller: 'builtin-robust' there, 'builtin' now" in other.stderr


def test_trials_side_by_side_score_as_one_at_a_time(tmp_path):
    """``--jobs 2``: the same trials in two worker processes give the same rows, in world order,
    and every finished trial reaches the results file."""
    args = ["--in-process", "--worlds", "5,10", "--seeds", "2", "--free-compute", "--json"]  # reproducible
    one = _bench(*args)
    results = tmp_path / "barn.jsonl"
    two = _bench(*args, "--jobs", "2", "--results", str(results))
    assert one.returncode == 0 and two.returncode == 0, (one.stderr, two.stderr)
    assert json.loads(two.stdout) == json.loads(one.stdout)
    trials = [json.loads(line)["trial"] for line in results.read_text().splitlines()[1:]]
    assert sorted((t["idx"], t["seed"]) for t in trials) == sorted((w["idx"], w["seed"]) for w in json.loads(one.stdout)["worlds"])
    bad = _bench(*args, "--jobs", "0")
    assert bad.returncode == 2 and "--jobs must be >= 1" in bad.stderr
