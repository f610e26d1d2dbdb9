"""``emos bench barn`` through the product: the Simulator and the navigation components as
supervised processes, scored by the harness's referee; and what the stack is (not) given."""
from __future__ import annotations

import json
import math
import os
import re
import subprocess
import sys

import numpy as np
import pytest

from emos.tools.barn.harness import BarnRules
from emos.tools.barn.stack import GROUND_TRUTH_TOPIC, NAV_COMPONENTS, StackOptions, build_system
from tests.runtime.helpers import REPO

pytestmark = [pytest.mark.sim, pytest.mark.process]


def test_the_stack_never_receives_true_poses():
    for rules in (BarnRules(), BarnRules(ideal=True), BarnRules(ideal=True, noisy_odometry=True)):
        sim, nav = build_system(StackOptions(world=3, rules=rules))
        outputs = {key: sim.get_out_topic(key) for key in sim.allowed_outputs}
        # The transform tree's world -> odom link is computed from the true pose: not published.
        assert outputs["tf"] is None and outputs["map"] is None
        assert outputs["ground_truth"].name == GROUND_TRUTH_TOPIC
        truth = {GROUND_TRUTH_TOPIC, "/tf"}
        for comp in nav:
            names = {t.name for t in comp.in_topics}
            assert not names & truth, (comp.component_name, names)
            assert comp.config.use_sim_time  # lock-step consumers, in simulated time
        # Odometry is what the robot's wheels (and IMU) give: never the truth, except in the
        # ideal configuration, whose point is ground-truth odometry (as in-process).
        expected = "wheel-imu" if not rules.ideal else ("wheel" if rules.noisy_odometry else "truth")
        assert sim.config.odometry_mode == expected
        assert sim.config.clock_mode.value == "lockstep"
        assert sorted(sim.config.lockstep_consumers) == sorted(c.component_name for c in nav)


def test_barn_world_through_supervised_processes(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(REPO))
    out = subprocess.run([sys.executable, "-m", "emos", "bench", "barn", "--worlds", "3", "--seeds", "1", "--json",
                          "--logs", str(tmp_path / "logs"), "--png", str(tmp_path / "png")],
                         cwd=REPO, capture_output=True, text=True, timeout=120, env=env)
    assert out.returncode == 0, out.stderr[-3000:]
    result = json.loads(out.stdout)
    assert set(result) == {"worlds", "summary"}
    (world,) = result["worlds"]
    # The same shape as in-process.
    assert set(world) == {"idx", "success", "collided", "timeout", "time_s", "metric", "seed", "metric_4t",
                          "deadline_misses"}
    assert set(result["summary"]) == {"success_rate", "collision_rate", "timeout_rate", "mean_metric", "metric_4t",
                                      "deadline_misses", "mean_time_s", "seeds"}
    assert world["idx"] == 3 and world["success"], out.stderr[-3000:]
    assert 2.0 < world["time_s"] < 30.0 and world["metric"] > 0.25
    assert result["summary"]["success_rate"] == 1.0
    assert "barn: world 3 (1/1) 1/1 success" in out.stderr  # the progress line
    assert list((tmp_path / "logs").iterdir()) == []  # --logs keeps only the logs of failed trials
    from PIL import Image

    from emos.actors.sim.render import ESTIMATE, TRAIL

    (png,) = (tmp_path / "png").iterdir()  # --png draws every trial
    pixels = np.asarray(Image.open(png).convert("RGB")).reshape(-1, 3)
    # The true trail, and the stack's localized poses beside it (where it believed it was).
    assert ((pixels == TRAIL).all(axis=1)).sum() > 100
    assert ((pixels == ESTIMATE).all(axis=1)).sum() > 20


def test_the_system_log_and_picture_of_a_failed_trial_are_kept(tmp_path):
    """``--logs DIR``: a trial that does not reach the goal leaves its system log, to see why;
    ``--png DIR`` draws it, with where the robot first touched."""
    worlds = tmp_path / "w.json"  # a cylinder on the start: the robot touches it at once
    worlds.write_text(json.dumps({"7": {"cylinders": [[-2.25, 3.2]], "path_length": 10.0}}))
    env = dict(os.environ, PYTHONPATH=str(REPO))
    out = subprocess.run([sys.executable, "-m", "emos", "bench", "barn", "--worlds-file", str(worlds), "--seeds", "1",
                          "--json", "--logs", str(tmp_path / "logs"), "--png", str(tmp_path / "png"),
                          "--results", str(tmp_path / "trials.jsonl")], cwd=REPO, capture_output=True, text=True,
                         timeout=180, env=env)
    assert out.returncode == 0, out.stderr[-3000:]
    (world,) = json.loads(out.stdout)["worlds"]
    assert world["collided"] and not world["success"]
    (log,) = (tmp_path / "logs").iterdir()
    assert log.name == f"world_007_seed_{world['seed']}.log"
    text = log.read_text()
    assert all(name in text for name in ("sim", *NAV_COMPONENTS)), text[-2000:]  # the whole system's log
    # The reason names the first contact, which lies on the cylinder (radius 0.075 m at (-2.25, 3.2)).
    (trial,) = [json.loads(line)["trial"] for line in (tmp_path / "trials.jsonl").read_text().splitlines()[1:]]
    # ... followed by the motion at the contact ("; rotation (v 0.00 m/s, omega 0.41 rad/s)").
    x, y = map(float, re.fullmatch(r"collision at \((\S+), (\S+)\); (rotation|arc|reversing|straight) \(v .*\)", trial["reason"]).groups()[:2])
    assert math.dist((x, y), (-2.25, 3.2)) < 0.2, trial["reason"]
    from PIL import Image

    (png,) = (tmp_path / "png").iterdir()
    assert png.name == f"barn_007_seed_{world['seed']}.png"
    pixels = np.asarray(Image.open(png).convert("RGB")).reshape(-1, 3)
    assert ((pixels == (255, 0, 0)).all(axis=1)).any()  # the contact's red ring
    assert ((pixels == (220, 30, 30)).all(axis=1)).any()  # the robot drawn as collided


def test_a_finished_trials_system_stops_in_the_background_and_leaves_nothing(tmp_path, monkeypatch):
    """``stop_in_background``: the result is returned once known and the system stops in a
    thread of the run's ``TrialSystems`` (the next trial starts meanwhile). After
    ``wait_stopped`` the system has exited, its folder is gone, its shared memory too, and the
    log of a failed trial holds the whole stop (copied after it)."""
    import glob
    import tempfile

    import psutil

    from emos.actors.sim.barn_worlds import load_barn_worlds
    from emos.tools.barn.process import TrialSystems, run_episode_process

    worlds = tmp_path / "w.json"  # a cylinder on the start: the robot touches it at once
    worlds.write_text(json.dumps({"7": {"cylinders": [[-2.25, 3.2]], "path_length": 10.0}}))
    # The trial's folder is made in a temporary directory of this test's own: another test's
    # trial of world 7 on the other worker makes and removes its folders in /tmp meanwhile.
    private_tmp = tmp_path / "tmp"
    private_tmp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(private_tmp))
    assert tempfile.gettempdir() == str(private_tmp)  # where run_episode_process's mkdtemp makes it

    def living_children() -> set[int]:
        # this worker may keep processes of other tests' module or session fixtures: count ours
        alive = set()
        for child in psutil.Process().children(recursive=True):
            try:
                if child.status() != psutil.STATUS_ZOMBIE:
                    alive.add(child.pid)
            except psutil.NoSuchProcess:
                pass  # gone meanwhile
        return alive

    children_before = living_children()
    systems = TrialSystems()
    kept = tmp_path / "failed.log"
    result = run_episode_process(load_barn_worlds(worlds)[7], StackOptions(world=7, barn_source=str(worlds)),
                                 wall_timeout=120.0, keep_log=kept, systems=systems, keep_log_on_success=False,
                                 stop_in_background=True)
    assert result.collided and not result.success
    systems.wait_stopped()
    assert not living_children() - children_before
    assert not glob.glob(os.path.join(private_tmp, "emos-barn-7-*")), "the trial's folder was left"
    text = kept.read_text()
    assert "bringup ended" in text and all(f"{name} stopped" in text for name in NAV_COMPONENTS), text[-2000:]
    run_id = re.search(r"system up: .* \(run (\S+)\)", text).group(1)  # other runs may share /dev/shm
    assert not [n for n in os.listdir("/dev/shm") if n.startswith(f"emos.{run_id}.")]


def test_a_simulator_whose_control_socket_fails_is_a_system_failure_not_the_end_of_the_run(tmp_path):
    """On a machine at load 40-50 the supervisor killed a trial's components as hung, and the
    referee's ``sim_status`` call got "connection reset by peer": an RpcConnectionError that ended
    a 600-trial run. It is the trial's system failing: ``SystemFailed``, counted as such."""
    import socket
    import threading

    from emos.core.control import control_socket
    from emos.core.reconfig import ComponentServices
    from emos.supervisor.launched import SystemFailed
    from emos.tools.barn.process import _sim_status
    from emos.transport.context import RunContext

    run_dir = tmp_path / "run"
    ctx = RunContext("test-reset", run_dir, owner=True)
    path = control_socket(ctx, "sim")
    server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    server.bind(str(path))
    server.listen(8)
    server.settimeout(0.2)
    stop = threading.Event()

    def hang_up() -> None:  # a Simulator that dies under every request
        while not stop.is_set():
            try:
                conn, _ = server.accept()
            except TimeoutError:
                continue
            conn.close()

    thread = threading.Thread(target=hang_up, daemon=True)
    thread.start()
    log = tmp_path / "system.log"
    log.write_text("[sim] no status for 2.01 s: killing it as hung\n")
    try:
        with pytest.raises(SystemFailed, match=r"world 7: the Simulator did not answer sim_status"):
            _sim_status(ComponentServices("sim", ctx, timeout=5.0), "world 7", log)
    finally:
        stop.set()
        thread.join(5)
        server.close()
        ctx.remove_everything()


def test_pose_drift_compares_the_belief_with_the_truth_of_the_same_time():
    from emos.tools.barn.process import _PoseDrift

    drift = _PoseDrift(keep=4)
    assert drift.describe() == ""  # nothing seen yet: the reason stays "time limit"
    for k in range(20):  # truth every 0.02 s along x
        drift.truth(k * 0.02, (k * 0.02, 0.0))
    drift.believed(0.30, (1.30, 0.0))  # at t = 0.30 the truth was x = 0.30 (kept: the latest 4-8)
    dist, believed, true = drift.error()
    assert math.isclose(dist, 1.0) and believed == (1.30, 0.0) and true == (0.30, 0.0)
    assert drift.describe() == "; the stack believed (1.30, 0.00), 1.00 m from the true (0.30, 0.00)"
    assert len(drift._truth) <= 8  # bounded: a 100 s trial publishes 5,000 true poses


def test_builtin_dynamic_stack_forgets_by_evidence_and_tracks_movers_in_the_scan():
    sim, (mapper, _, controller, _) = build_system(StackOptions.for_controller("builtin-dynamic", world=3, dynabarn=True))
    assert sim.config.world == "dynabarn:3" and sim.config.spawn == (0.0, 0.0, 0.0)  # the set's start, not BARN's
    assert mapper.config.memory_decay is not None and mapper.config.mapping_bounds[2] > 20.0  # window to the goal
    algo = controller.algorithms_config
    assert algo.movers is not None and algo.response is not None  # builtin-robust's response model too
    assert not controller.config.use_direct_sensor and controller.get_in_topic("sensor_data").name == "/scan"
    assert controller.get_in_topic("local_map").name == mapper.get_out_topic("mapping").name  # the forgetting memory
    static = build_system(StackOptions.for_controller("builtin-robust", world=3))[1]
    assert static[0].config.memory_decay is None and static[2].algorithms_config.movers is None
    # Static worlds: the latest scan's grid, placed at its scan's pose (the memory piles up noise).
    assert static[0].config.local_map_frame == "world" and mapper.config.local_map_frame == "robot"
    assert static[2].get_in_topic("local_map").name == static[0].get_out_topic("local_map").name


def test_moving_obstacle_world_through_supervised_processes():
    # The trial of test_sim_dynabarn_nav (world 3, seed of trial 0): in-process builtin-robust
    # collides with a crosser there; builtin-dynamic (the --dynabarn default) through the
    # component processes must not.
    env = dict(os.environ, PYTHONPATH=str(REPO))
    out = subprocess.run([sys.executable, "-m", "emos", "bench", "barn", "--dynabarn", "--worlds", "3", "--seeds", "1"],
                         cwd=REPO, capture_output=True, text=True, timeout=240, env=env)
    assert out.returncode == 0, out.stderr[-3000:]
    assert "controller builtin-dynamic" in out.stdout and "supervised processes" in out.stdout, out.stdout
    row = next(line.split() for line in out.stdout.splitlines() if line.split()[:1] == ["3"])
    success, collided, time_s = float(row[1]), float(row[2]), float(row[4])
    assert success == 1.0 and collided == 0.0, (out.stdout, out.stderr[-3000:])
    assert time_s < 20.0  # 20 m: it waits for crossers, it does not crawl


def test_sigterm_stops_the_trials_in_flight_at_once_and_records_none_of_them(tmp_path):
    """Stopping a long run must not wait for every trial in flight to finish (minutes each when
    one times out), leave their systems running, or record them as failures (a resumed run
    would then skip them)."""
    import signal
    import time

    import psutil

    results = tmp_path / "r.jsonl"
    env = dict(os.environ, PYTHONPATH=str(REPO))
    bench = subprocess.Popen([sys.executable, "-m", "emos", "bench", "barn", "--worlds", "3,4", "--seeds", "2",
                              "--jobs", "2", "--json", "--results", str(results)],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        me = psutil.Process(bench.pid)
        deadline = time.monotonic() + 120
        systems: list[psutil.Process] = []
        while len(systems) < 2:  # both trials' systems are up and driving
            assert bench.poll() is None and time.monotonic() < deadline, bench.stderr.read() if bench.poll() else "too slow"
            systems = [p for p in me.children() if "emos-barn-" in " ".join(p.cmdline())]
            time.sleep(0.5)
        everything = systems + [c for p in systems for c in p.children(recursive=True)]
        time.sleep(3.0)
        recorded_before = results.read_text().splitlines() if results.exists() else []
        bench.send_signal(signal.SIGTERM)
        _, err = bench.communicate(timeout=180)  # bounds a hang only
    finally:
        if bench.poll() is None:
            bench.kill()
    assert bench.returncode == 143, err[-3000:]
    # At once: the trials in flight were given up (each system's own stop), not driven to their
    # end, which would have recorded them. A count of results, not seconds: a busy machine may
    # take long to stop, never to finish a trial.
    recorded_after = results.read_text().splitlines() if results.exists() else []
    assert recorded_after[1:] == recorded_before[1:], (recorded_before, recorded_after)
    assert "Traceback" not in err and "system failure" not in err, err[-3000:]
    time.sleep(1.0)
    assert not [p.pid for p in everything if p.is_running() and p.status() != psutil.STATUS_ZOMBIE]
    lines = results.read_text().splitlines() if results.exists() else []
    recorded = [json.loads(line)["trial"] for line in lines[1:]]
    assert all(t["reason"] == "goal" or t["reason"].startswith(("time limit", "collision")) for t in recorded), recorded


def test_a_trials_system_dies_with_a_benchmark_killed_outright():
    """SIGKILL runs no handler and no `finally`: the trial's system must still stop (it gets
    SIGTERM when the benchmark process dies) and leave no shared memory behind. Before, it went
    on driving, holding its rings, until stopped by hand."""
    import shutil
    import signal
    import time

    import psutil

    env = dict(os.environ, PYTHONPATH=str(REPO))
    code = ("from emos.tools.barn.harness import BarnRules; from emos.tools.barn.process import run_episode_process; "
            "from emos.tools.barn.stack import StackOptions; from emos.actors.sim.barn_worlds import load_barn_worlds; "
            "run_episode_process(load_barn_worlds()[3], StackOptions(world=3, rules=BarnRules(ideal=True)), wall_timeout=120.0)")
    bench = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    try:
        me = psutil.Process(bench.pid)
        deadline = time.monotonic() + 120
        systems: list[psutil.Process] = []
        while not systems:
            assert bench.poll() is None and time.monotonic() < deadline, "the trial's system did not start"
            systems = [p for p in me.children() if "emos-barn-" in " ".join(p.cmdline())]
            time.sleep(0.3)
        run_id = None
        while run_id is None and time.monotonic() < deadline:  # its rings exist: it is running
            names = [n for n in os.listdir("/dev/shm") if n.startswith(f"emos.{systems[0].pid}-")]
            run_id = names[0].split(".")[1] if names else None
            time.sleep(0.3)
        assert run_id is not None, "the trial's system made no rings"
        everything = systems + systems[0].children(recursive=True)
        # The harness's temporary folder (the recipe): a killed harness cannot remove it, we do.
        trial_dir = next(os.path.dirname(arg) for arg in systems[0].cmdline() if "emos-barn-" in arg)
        bench.send_signal(signal.SIGKILL)
        bench.wait(10)
    finally:
        if bench.poll() is None:
            bench.kill()
    def alive() -> list[psutil.Process]:
        return [p for p in everything if p.is_running() and p.status() != psutil.STATUS_ZOMBIE]

    gone_by = time.monotonic() + 45
    while time.monotonic() < gone_by and alive():
        time.sleep(0.5)
    left = alive()
    for p in left:  # a failing run must not leave its system driving for the rest of the suite
        p.terminate()
    shutil.rmtree(trial_dir, ignore_errors=True)
    assert not [p.pid for p in left]
    assert not [n for n in os.listdir("/dev/shm") if n.startswith(f"emos.{run_id}.")]


def test_a_recorded_trial_replays_through_the_stacks_mapper_to_the_same_poses(tmp_path):
    """``scripts/barn_pose_replay.py``: the replay of a recorded trial's scans and odometry
    through the mapper as the stack configures it lands where the stack's own belief did (so a
    matcher change can be tried offline on a real trial), and both are compared with the truth."""
    env = dict(os.environ, PYTHONPATH=str(REPO))
    script = str(REPO / "scripts" / "barn_pose_replay.py")
    trace = tmp_path / "w3.npz"
    out = subprocess.run([sys.executable, script, "record", "--world", "3", "--seed", "1", "-o", str(trace)],
                         cwd=tmp_path, capture_output=True, text=True, timeout=180, env=env)
    assert out.returncode == 0, out.stderr[-3000:]
    assert "world 3 seed 1: goal" in out.stdout and trace.exists() and trace.with_suffix(".png").exists()
    out = subprocess.run([sys.executable, script, "replay", str(trace), "--every", "0.001"],
                         cwd=tmp_path, capture_output=True, text=True, timeout=180, env=env)
    assert out.returncode == 0, out.stderr[-3000:]
    # Every scan's row; a "-" where the trial ended before the stack's belief of that scan was
    # recorded (the last scan or two: a busy machine's recorder may not have read it yet).
    rows = [line.split() for line in out.stdout.splitlines() if re.match(r"\s*\d+\.\d\s", line)]
    assert len(rows) >= 200, out.stdout
    compared = np.array([list(map(float, r)) for r in rows if "-" not in r])
    assert len(compared) >= len(rows) - 3, out.stdout
    replayed, believed, odometry = compared[:, 1:3], compared[:, 3:5], compared[:, 5:7]
    # Both pair each scan with the odometry at its stamp and take in every scan: the same
    # poses to the printed millimetre, where the odometry alone is off by decimetres.
    assert np.abs(replayed - believed).max() < 0.0015, out.stdout
    assert np.abs(odometry).max() > 0.1, out.stdout  # real wheel + IMU odometry, not the truth
