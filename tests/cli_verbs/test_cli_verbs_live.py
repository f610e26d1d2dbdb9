"""Issue 33 item 4 and defect D4 on real runs: `emos service list/call` and `emos action
list/send_goal` drive the Planner's path recording and its plan_path action from the command
line (feedback as it arrives, the result, Ctrl-C cancels the goal on the component), and with
several runs live the CLI refuses to guess which one is meant, while options go before or
after the verb."""
from __future__ import annotations

import csv
import json
import signal
import subprocess
import sys
import threading

import pytest

from tests.runtime.helpers import HANG_S, LISTENER, REPO, SystemUnderTest, ctrl_c_as_at_a_terminal

pytestmark = pytest.mark.process

# The robot (a kinematic base driven by /cmd_vel) in a room with a map; the Planner serves its
# plan_path action and its three path services. No controller: the robot moves only when the
# test publishes /cmd_vel, so a goal away from it runs (and sends feedback) until canceled.
PLANNER_RUN = """
from emos.actors.nav import RobotConfig, RobotType, RobotGeometry, LinearCtrlLimits, AngularCtrlLimits
from emos.actors.nav.components import MapServer, MapServerConfig, Planner, PlannerConfig
from tests.nav.components.fake_base import FakeBase, write_room_map
robot = RobotConfig(model_type=RobotType.DIFFERENTIAL_DRIVE, geometry_type=RobotGeometry.Type.CYLINDER,
                    geometry_params=np.array([0.15, 0.3]),
                    ctrl_vx_limits=LinearCtrlLimits(max_vel=0.5, max_acc=1.5, max_decel=2.5),
                    ctrl_omega_limits=AngularCtrlLimits(max_vel=1.5, max_acc=3.0, max_decel=3.0))
map_server = MapServer(component_name="map_server", config=MapServerConfig(map_file_path=write_room_map("room.yaml")))
planner = Planner(component_name="planner", config=PlannerConfig(planner_id="CostToGo", loop_rate=4.0))
planner.run_type = "ActionServer"
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[FakeBase(start=(1.0, 1.0, 0.0))])
launcher.kompass(components=[map_server, planner], multiprocessing=True)
launcher.robot = robot
launcher.bringup()
"""
FAR_GOAL = '{"goal": {"position": {"x": 2.0, "y": 3.0}}}'  # reachable round the wall; the robot does not drive there


@pytest.fixture(scope="module")
def planner_run(private_runtime, tmp_path_factory):
    s = SystemUnderTest(tmp_path_factory.mktemp("planner_run"), PLANNER_RUN, env={"PYTHONPATH": str(REPO)})
    try:
        s.wait_up(components=["base", "map_server", "planner"])
        yield s
    finally:
        code = s.stop()
        assert code == 0, s.output()
        assert s.leftovers() == []


def emos(*args: str, timeout: float = HANG_S) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "emos", *args], check=False, capture_output=True, text=True, timeout=timeout)


def lines(text: str, label: str) -> list[dict]:
    return [json.loads(line.split(": ", 1)[1]) for line in text.splitlines() if line.startswith(label + ": ")]


def test_service_list_and_call_record_a_path_driven_from_the_cli(planner_run, tmp_path):
    run = planner_run.run_dir.name
    listed = emos("service", "list", "planner")  # the only live run: used, and named on stderr
    assert listed.returncode == 0, listed.stderr
    said = listed.stderr.strip().splitlines()
    assert len(said) == 1 and said[0].startswith(f"emos: using run {run} (emos run "), listed.stderr
    assert ("/planner/start_path_recording [kompass_interfaces/msg/StartPathRecording_Request -> "
            "kompass_interfaces/msg/StartPathRecording_Response]") in listed.stdout.splitlines()
    assert {"/planner/save_plan_to_file", "/planner/load_plan_from_file"} <= {line.split()[0] for line in listed.stdout.splitlines()}
    # The request is checked against the request type before anything is sent: field and type named.
    bad = emos("service", "call", "planner", "start_path_recording", '{"recording_time_step": "fast"}', "--run", run)
    assert bad.returncode == 2, bad
    assert bad.stderr.strip() == ("emos service call planner start_path_recording: bad REQUEST for "
                                  "kompass_interfaces/msg/StartPathRecording_Request: field recording_time_step expects a float, "
                                  "got str 'fast'"), bad.stderr
    unknown = emos("service", "call", "--run", run, "planner", "start_path_recording", '{"step": 0.1}')
    assert unknown.returncode == 2 and "has no field 'step'; fields are recording_time_step" in unknown.stderr, unknown.stderr
    wrong_kind = emos("service", "call", "planner", "plan_path", "--run", run)
    assert wrong_kind.returncode == 1 and "/planner/plan_path of component 'planner' is an action, not a service" in wrong_kind.stderr
    # Path recording, driven from the command line: start, drive the robot, save.
    started = emos("service", "call", "planner", "/planner/start_path_recording", '{"recording_time_step": 0.05}', "--run", run)
    assert started.returncode == 0, started.stderr
    assert json.loads(started.stdout)["success"] is True
    drive = emos("topic", "pub", "/cmd_vel", "Twist", '{"linear": {"x": 0.3}}', "--rate", "20", "--count", "30", "--run", run)
    assert drive.returncode == 0, drive.stderr
    saved = emos("service", "call", "planner", "save_plan_to_file",
                 json.dumps({"file_location": str(tmp_path), "file_name": "recorded.csv"}), "--run", run)
    assert saved.returncode == 0, saved.stderr
    answer = json.loads(saved.stdout)
    assert answer["success"] is True and "recorded path" in answer["message"], answer
    with open(tmp_path / "recorded.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    xs = [float(r["x"]) for r in rows]
    assert len(xs) >= 3 and xs == sorted(xs) and xs[-1] - xs[0] > 0.1, xs  # it recorded the drive along +x


def test_action_send_goal_prints_feedback_and_the_result(planner_run):
    run = planner_run.run_dir.name
    listed = emos("action", "list", "--run", run)
    assert listed.returncode == 0, listed.stderr
    assert ("/planner/plan_path [goal kompass_interfaces/msg/PlanPath_Goal, feedback kompass_interfaces/msg/PlanPath_Feedback, "
            "result kompass_interfaces/msg/PlanPath_Result]") in listed.stdout.splitlines()
    bad = emos("action", "send_goal", "planner", "plan_path", '{"goal": {"position": {"x": "far"}}}', "--run", run)
    assert bad.returncode == 2 and "bad GOAL for kompass_interfaces/msg/PlanPath_Goal: field goal.position.x expects a float, got str 'far'" \
        in bad.stderr, bad.stderr
    missing = emos("action", "send_goal", "planner", "follow", "--run", run)
    assert missing.returncode == 1 and "has no action 'follow'; its actions: /planner/plan_path" in missing.stderr, missing.stderr
    # A goal where the robot already is ends at once: the result, and success.
    near = emos("action", "send_goal", "--run", run, "planner", "plan_path",
                '{"goal": {"position": {"x": 1.1, "y": 1.0}}, "end_tolerance": {"lateral_distance_error": 0.8}}')
    assert near.returncode == 0, near.stderr
    out = near.stdout.splitlines()
    assert out[0].startswith("sending goal ") and out[0].endswith(" to /planner/plan_path")
    assert lines(near.stdout, "result")[0]["message"] == "goal reached" and out[-1] == "goal finished: succeeded"
    # A goal the robot does not drive to: feedback as the planner re-plans, until --timeout cancels it.
    far = emos("action", "send_goal", "planner", "plan_path", FAR_GOAL, "--timeout", "3", "--run", run)
    assert far.returncode == 1, far.stderr
    feedback = lines(far.stdout, "feedback")
    assert feedback and all(f["plan_length"] > 2.0 for f in feedback), far.stdout
    assert "--timeout" in far.stderr and "cancel acknowledged by /planner/plan_path" in far.stderr, far.stderr
    assert lines(far.stdout, "result")[-1]["message"] == "cancelled" and far.stdout.splitlines()[-1] == "goal finished: canceled"


@pytest.mark.parametrize("when", ["after_feedback", "right_after_sending"])
def test_ctrl_c_cancels_the_goal_on_the_component_and_exits_130(planner_run, when):
    """SIGINT cancels the goal on the component, waits for the acknowledgement and for the goal
    to end (the component's own "cancelled" result proves it ended there), and exits 130. Sent
    right after the goal went out, the cancel may reach the component before the goal does: it
    is asked again until the component knows the goal."""
    proc = subprocess.Popen([sys.executable, "-m", "emos", "action", "send_goal", "planner", "plan_path", FAR_GOAL,
                             "--run", planner_run.run_dir.name], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=ctrl_c_as_at_a_terminal)
    seen: list[str] = []
    wanted = "feedback: " if when == "after_feedback" else "sending goal "
    ready = threading.Event()

    def read() -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            seen.append(line.rstrip("\n"))
            if line.startswith(wanted):
                ready.set()

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        assert ready.wait(HANG_S), seen
        proc.send_signal(signal.SIGINT)
        assert proc.wait(HANG_S) == 130
        reader.join(HANG_S)
        err = proc.stderr.read() if proc.stderr else ""
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert "interrupted (Ctrl-C): canceling goal" in err and "cancel acknowledged by /planner/plan_path" in err, err
    assert "Traceback" not in err, err
    assert lines("\n".join(seen), "result")[-1]["message"] == "cancelled", seen
    assert seen[-1] == "goal finished: canceled", seen


def test_with_two_runs_live_the_cli_asks_which_and_options_go_anywhere(planner_run, tmp_path):
    other = SystemUnderTest(tmp_path, LISTENER).wait_up(components=["listener"])
    try:
        run = planner_run.run_dir.name
        runs = {run, other.run_dir.name}
        for args in (("status",), ("topic", "list"), ("component", "info", "planner")):
            refused = emos(*args)
            assert refused.returncode == 1, (args, refused)
            said = refused.stderr.strip().splitlines()
            assert said[0] == "emos: 2 EMOS systems are running; say which one with --run RUN_ID:", (args, said)
            assert {line.split()[0] for line in said[1:]} == runs and refused.stdout == "", (args, said)
        # --run before or after the verb means the same (every form: test_cli_verbs_parsing.py).
        for args in (("component", "info", "--run", run, "planner"), ("component", "--run", run, "info", "planner")):
            info = emos(*args)
            assert info.returncode == 0, (args, info.stderr)
            assert json.loads(info.stdout)["component"] == "planner" and info.stderr == "", args  # --run given: no "using" line
        listing = emos("topic", "list", "--run", run)
        assert listing.returncode == 0 and "/planner/status" in listing.stdout, listing.stderr
        for args in (("service", "--run", run, "list", "planner"), ("action", "--run", run, "list", "planner")):
            assert emos(*args).returncode == 0, args
        record = emos("record", "/planner/status", "-o", str(tmp_path / "two.mcap"), "--run", run, "/base/status", "--duration", "1", "-q")
        assert record.returncode == 0, record.stderr  # options between the topics of `emos record`
    finally:
        assert other.stop() == 0
