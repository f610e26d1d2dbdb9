"""Threaded mode has the process mode's semantics; the CLI sees and feeds a live system."""
import json
import subprocess
import sys

import pytest

from tests.runtime.helpers import HANG_S, SystemUnderTest, wait_until

pytestmark = pytest.mark.process

THREADED = """
class Counter(BaseComponent):
    def custom_on_activate(self):
        self.t0 = time.monotonic()
        self.count = 0
    def _execution_step(self):
        self.count += 1
        if self.out_topics:
            self.publish("count", M.Int64(data=self.count))
        mode = os.environ.get("MISBEHAVE", "")
        if self.component_name == "bad" and time.monotonic() - self.t0 > 0.3:
            if mode == "crash":
                self.node.request_exit(1)
            elif mode == "hang":
                time.sleep(3.0)  # blocks this component's loop: no heartbeat
        self.health_status.set_healthy()

good = Counter(component_name="good", outputs=[Topic(name="count", msg_type="Int64")])
bad = Counter(component_name="bad")
launcher = Launcher(multi_processing=False, heartbeat_timeout=0.5, max_restarts=50, max_seconds=60)
launcher.add_pkg(components=[good, bad])
launcher.bringup()
"""


def _restarts_of(system, name):
    return [e for e in system.events() if e["event"] == "restarted" and e["child"] == name]


def test_threaded_mode_restarts_a_crashed_component(tmp_path):
    system = SystemUnderTest(tmp_path, THREADED, env={"MISBEHAVE": "crash"}).wait_up(components=["good", "bad"])
    try:
        wait_until(lambda: len(_restarts_of(system, "bad")) >= 2, what="two restarts of the crashing thread")
        exits = [e for e in system.events() if e["event"] == "exit"]
        assert {e["child"] for e in exits} == {"bad"} and exits[0]["reason"] == "crash"
        assert system.workers()["good"]["mode"] == "thread"
        assert system.pid("good") == system.proc.pid  # threads live in the launcher process
    finally:
        assert system.stop() == 0
    assert system.leftovers() == []


def test_threaded_mode_detects_a_hung_component(tmp_path):
    system = SystemUnderTest(tmp_path, THREADED, env={"MISBEHAVE": "hang"}).wait_up(components=["good", "bad"])
    try:
        wait_until(lambda: _restarts_of(system, "bad"), timeout=HANG_S, what="a restart of the hung thread")
        exits = [e for e in system.events() if e["event"] == "exit" and e["child"] == "bad"]
        assert exits[0]["reason"] == "hang"
    finally:
        assert system.stop() == 0


def _emos(*args, timeout=30):
    return subprocess.run([sys.executable, "-m", "emos", *args], capture_output=True, text=True, timeout=timeout)


def test_cli_status_and_topic_commands_against_a_live_system(tmp_path):
    system = SystemUnderTest(tmp_path, THREADED.replace("multi_processing=False", "multi_processing=True")).wait_up(components=["good", "bad"])
    try:
        run = ["--run", system.run_dir.name]
        status = _emos("status", "--json", *run)
        assert status.returncode == 0, status.stderr
        tree = json.loads(status.stdout)["tree"]
        workers = {w["name"]: w for g in tree["children"] for w in g["children"]}
        assert workers["good"]["state"] == "active" and workers["good"]["health"] == "HEALTHY"
        assert workers["good"]["pid"] != system.proc.pid and workers["good"]["rss_mb"] > 0
        assert "cpu_percent" in workers["good"]
        table = _emos("status", *run).stdout
        assert "good" in table and "active" in table and "RSS MB" in table

        listing = json.loads(_emos("topic", "list", "--json", *run).stdout)
        assert listing["/count"]["type"] == "std_msgs/msg/Int64" and listing["/count"]["publishers"] == ["good"]
        assert "/good/status" in listing

        echo = _emos("topic", "echo", "/count", "-n", "2", *run)
        values = [json.loads(block)["data"] for block in echo.stdout.split("---") if block.strip()]
        assert len(values) == 2 and values[1] == values[0] + 1

        hz = _emos("topic", "hz", "/count", "--window", "1", "--reports", "1", *run)
        rate = float(hz.stdout.split(":")[1].split("Hz")[0])
        assert 50 < rate < 150, hz.stdout  # loop_rate defaults to 100 Hz

        pub = _emos("topic", "pub", "/command", "Twist", '{"linear": {"x": 0.5}}', *run)
        assert pub.returncode == 0 and "published 1 Twist" in pub.stdout
        bad = _emos("topic", "pub", "/command", "Twist", '{"linear": {"q": 1}}', *run)
        assert bad.returncode != 0 and "has no field 'q'" in bad.stderr
    finally:
        assert system.stop() == 0


def test_cli_without_a_running_system_says_so():
    out = _emos("status", "--run", "1-1")
    assert out.returncode != 0 and "no running system" in out.stderr


def test_main_job_demo_runs_and_reports_intact_frames(tmp_path):
    out = subprocess.run([sys.executable, "-m", "emos", "run", "recipes/sensor_demo.py", "--duration", "8"], capture_output=True, text=True, timeout=90, cwd=str(__import__("pathlib").Path(__file__).resolve().parents[2]))
    assert out.returncode == 0, out.stdout + out.stderr
    report = {line.split()[0]: line.split() for line in out.stdout.splitlines() if line.strip().startswith(("camera ", "lidar ")) and " received " in line}
    for stream, min_msgs in (("camera", 120), ("lidar", 80)):
        words = report[stream]
        received, corrupt, lost = int(words[2]), int(words[4]), int(words[6])
        assert received >= min_msgs and corrupt == 0 and lost == 0, words
    assert "crasher                  restarted after: 2 killed" in out.stdout or "restarted after: 2 killed" in out.stdout
