"""Shipped chaos scenarios, short versions, through the real CLI against real process trees;
plus the scenario file's error messages and the checker's judgement of histories."""
import json
import subprocess
import sys

import pytest

from emos.chaos.checkers import judge_faults
from emos.chaos.history import History
from emos.chaos.nemesis import NemesisError
from emos.chaos.scenario import Scenario, ScenarioError, shipped_scenarios

pytestmark = pytest.mark.process


def _chaos(tmp_path, *args, timeout=240):
    proc = subprocess.run([sys.executable, "-m", "emos", "chaos", "run", *args, "--short", "--json", "--out", str(tmp_path)],
                          capture_output=True, text=True, timeout=timeout)
    summary = json.loads(proc.stdout.strip().splitlines()[-1]) if proc.stdout.strip() else None
    return proc, summary


def _runs(tmp_path):
    (results,) = list(tmp_path.glob("*/results.json"))
    return json.loads(results.read_text())["runs"]


def test_sensor_kills_short_recovers_every_fault_and_leaks_nothing(tmp_path):
    proc, summary = _chaos(tmp_path, "sensor-kills")
    assert summary is not None, proc.stderr[-3000:]
    run = _runs(tmp_path)[0]
    assert proc.returncode == 0, run["problems"]
    assert summary["faults"] >= 5 and summary["recovered"] == summary["faults"]
    assert summary["leaks"] == {"shm": 0, "procs": 0, "dirs": 0} and summary["corrupt"] == 0
    kinds = {o["nemesis"] for o in run["outcomes"]}
    assert {"kill", "hang", "starve", "kill_zygote"} <= kinds
    assert sum(run["received"].values()) > 100  # the observer really saw the sensors
    assert (tmp_path / next(tmp_path.iterdir()).name / "timeline-1.png").stat().st_size > 10_000


def test_escalation_short_gives_up_with_exit_code_3_and_nothing_left(tmp_path):
    proc, summary = _chaos(tmp_path, "escalation")
    assert summary is not None, proc.stderr[-3000:]
    run = _runs(tmp_path)[0]
    assert proc.returncode == 0, run["problems"]
    assert run["exit_code"] == 3
    assert summary["leaks"] == {"shm": 0, "procs": 0, "dirs": 0}


def test_kill_soak_short_recovers_every_kill_and_leaks_nothing(tmp_path):
    proc, summary = _chaos(tmp_path, "kill-soak")
    assert summary is not None, proc.stderr[-3000:]
    run = _runs(tmp_path)[0]
    assert proc.returncode == 0, run["problems"]
    assert summary["faults"] >= 10 and summary["recovered"] == summary["faults"]
    assert summary["leaks"] == {"shm": 0, "procs": 0, "dirs": 0} and summary["corrupt"] == 0


def test_fallback_ladder_short_walks_the_declared_ladder_for_every_break(tmp_path):
    proc, summary = _chaos(tmp_path, "fallback-ladder")
    assert summary is not None, proc.stderr[-3000:]
    run = _runs(tmp_path)[0]
    assert proc.returncode == 0, run["problems"]
    ladder = run["ladder"]
    assert ladder["violations"] == [] and ladder["complete"] >= 2 and ladder["attempts"] >= 10
    kinds = {o["nemesis"] for o in run["outcomes"]}
    assert {"method", "kill_monitor", "term_deaf"} <= kinds and all(o["recovered"] for o in run["outcomes"])
    assert run["received"]["/alarms"] >= 2  # the Monitor's event fired, also after the Monitor was killed


def test_point_navigation_short_reaches_both_goals_under_faults(tmp_path):
    proc, summary = _chaos(tmp_path, "point-navigation", timeout=300)
    assert summary is not None, proc.stderr[-3000:]
    run = _runs(tmp_path)[0]
    assert proc.returncode == 0, run["problems"]
    assert run["goals"] == 2 and run["goals_reached"] == 2 and run["collisions"] == 0
    assert run["faults"] >= 5 and run["recovered"] + run["cut"] == run["faults"]
    assert run["stale_violations"] == [] and run["received"]["/cmd_vel"] > 100
    assert summary["leaks"] == {"shm": 0, "procs": 0, "dirs": 0}


def test_every_shipped_scenario_loads():
    assert {"sensor-kills", "escalation", "kill-soak", "point-navigation", "fallback-ladder"} <= set(shipped_scenarios())
    for name in shipped_scenarios():
        assert Scenario.load(name).nemeses
        assert Scenario.load(name, short=True).duration <= Scenario.load(name).duration


def test_scenario_errors_name_the_file_and_the_key(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("recipe: nowhere.py\n")
    with pytest.raises(ScenarioError, match="bad.yaml: recipe 'nowhere.py' not found"):
        Scenario.load(bad)
    recipe = tmp_path / "r.py"
    recipe.write_text("")
    bad.write_text("recipe: r.py\nschedule:\n  nemeses:\n    - {kind: kil}\n")
    with pytest.raises(NemesisError, match=r"schedule.nemeses\[0\]: unknown nemesis kind 'kil'; did you mean kill"):
        Scenario.load(bad)
    bad.write_text("recipe: r.py\nduraton: 3\n")
    with pytest.raises(ScenarioError, match="unknown key.*duraton"):
        Scenario.load(bad)
    with pytest.raises(ScenarioError, match="no scenario file 'nope'.*sensor-kills"):
        Scenario.load("nope")


def test_checker_judges_restart_recovery_from_the_history():
    h = History()
    h._records = []
    from emos.chaos.history import Record

    h._records += [
        Record(1.0, "status", "cam", {"pid": 10, "health": "HEALTHY"}),
        Record(2.0, "fault", "kill", {"target": "cam", "pid": 10, "expects": "restart"}),
        Record(2.1, "status", "cam", {"pid": 11, "health": "UNKNOWN"}),
        Record(2.3, "status", "cam", {"pid": 11, "health": "HEALTHY"}),
        Record(3.0, "fault", "kill", {"target": "lidar", "pid": 20, "expects": "restart"}),
        Record(3.5, "status", "lidar", {"pid": 20, "health": "HEALTHY"}),  # same pid: not a recovery
    ]
    cam, lidar = judge_faults(h, {})
    assert cam.recovered and cam.recover_ms == pytest.approx(300.0)
    assert not lidar.recovered and lidar.recover_ms is None


def test_model_drop_short_answers_every_question_through_the_backup(tmp_path):
    proc, summary = _chaos(tmp_path, "model-drop")
    assert summary is not None, proc.stderr[-3000:]
    run = _runs(tmp_path)[0]
    assert proc.returncode == 0, run["problems"]
    assert run["requests"] >= 12 and run["answered"] >= run["requests"] - 2 and not run["unanswered"]  # 12: the scenario's short floor
    assert run["answer_ms_at_fault"]["n"] >= 1  # a question was in flight when the server dropped
    assert summary["leaks"] == {"shm": 0, "procs": 0, "dirs": 0}
    log = (tmp_path / next(tmp_path.iterdir()).name / "run-1.log").read_text()
    assert "switching to 'backup'" in log
