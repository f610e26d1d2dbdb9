"""Issue 31, items 16 and 18: every start of a component is counted over the run with its reason
(crash, group restart, escalation, fallback, requested), in ``emos status --json`` and in the run
summary; and after a group restart the fallbacks never act on what the previous incarnation
reported."""
import json
import subprocess
import sys
import time

import pytest

from tests.runtime.helpers import SystemUnderTest, wait_until

pytestmark = pytest.mark.process

CRASHY = """
FLAGS = os.environ["FLAGS"]

class Crashy(BaseComponent):
    '''Ends itself (exit code 1) 0.3 s after activation in its first CRASHES incarnations.'''
    def custom_on_activate(self):
        self.t0 = time.monotonic()
        self.crash = len(os.listdir(FLAGS)) < int(os.environ["CRASHES"])
    def _execution_step(self):
        self.health_status.set_healthy()
        if self.crash and time.monotonic() - self.t0 > 0.3:
            open(os.path.join(FLAGS, f"crash-{time.time():.6f}"), "w").close()
            os._exit(1)

class Steady(BaseComponent):
    def _execution_step(self):
        self.health_status.set_healthy()
"""


def _start(tmp_path, body: str, crashes: int) -> tuple[SystemUnderTest, object]:
    flags = tmp_path / "flags"
    flags.mkdir()
    system = SystemUnderTest(tmp_path, CRASHY + body, env={"FLAGS": str(flags), "CRASHES": str(crashes)}).wait_up()
    return system, flags


def _status_json(system: SystemUnderTest) -> dict[str, dict]:
    out = subprocess.run([sys.executable, "-m", "emos", "status", "--json", "--run", system.run_dir.name],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stdout + out.stderr
    nodes: dict[str, dict] = {}

    def walk(node: dict) -> None:
        nodes[f"{node.get('kind')}:{node.get('name')}"] = node
        for child in node.get("children", []):
            walk(child)

    walk(json.loads(out.stdout)["tree"])
    return nodes


def _summary_line(output: str, name: str) -> str:
    summary = output.split("EMOS run")[-1]
    return next(line.strip() for line in summary.splitlines() if line.strip().startswith(name + " "))


def _restarts(node: dict) -> tuple[int, dict, str | None]:
    return node["restarts"], node["restart_reasons"], node["last_restart_reason"]


def test_group_restarts_and_requested_restarts_are_counted_with_their_reasons(tmp_path):
    system, flags = _start(tmp_path, """
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[Crashy(component_name="crashy"), Steady(component_name="sib")], package_name="pair",
                 strategy="one_for_all", max_restarts=10, max_seconds=60)
launcher.bringup()
""", crashes=2)
    try:
        wait_until(lambda: len(list(flags.iterdir())) == 2, timeout=60, what="two crashes")
        wait_until(lambda: system.state("crashy") == "active" and system.state("sib") == "active", timeout=30, what="both back")
        nodes = _status_json(system)
        assert _restarts(nodes["worker:crashy"]) == (2, {"crash": 2}, "crash")
        assert _restarts(nodes["worker:sib"]) == (2, {"group restart": 2}, "group restart")
        # A restart asked through the supervisor socket (as `emos component call` does) is a request.
        sib = system.pid("sib")
        out = subprocess.run([sys.executable, "-m", "emos", "component", "call", "sib", "restart", "--run", system.run_dir.name],
                             capture_output=True, text=True, timeout=60)
        assert out.returncode == 0, out.stdout + out.stderr
        system.wait_new_pid("sib", sib, timeout=30)
        wait_until(lambda: system.state("crashy") == "active", timeout=30, what="crashy back after the group restart")
        nodes = _status_json(system)
        assert _restarts(nodes["worker:sib"]) == (3, {"group restart": 2, "requested": 1}, "requested")
        assert _restarts(nodes["worker:crashy"]) == (3, {"crash": 2, "group restart": 1}, "group restart")
        assert nodes["supervisor:pair"]["restarts"] == 6
        exits = [(e["child"], e["reason"], e.get("by")) for e in system.events() if e["event"] == "exit"]
        assert exits == [("crashy", "crash", None), ("crashy", "crash", None), ("sib", "restart_requested", "requested")]
        table = subprocess.run([sys.executable, "-m", "emos", "status", "--run", system.run_dir.name], capture_output=True, text=True, timeout=60)
        sib_row = next(line for line in table.stdout.splitlines() if line.strip().startswith("sib "))
        assert sib_row.split()[4] == "3" and sib_row.rstrip().endswith("requested"), table.stdout
    finally:
        assert system.stop() == 0
    out = system.output()
    assert _summary_line(out, "crashy") == "crashy                   restarted after: 2 crash, 1 group restart", out[-2000:]
    assert _summary_line(out, "sib") == "sib                      restarted after: 2 group restart, 1 requested", out[-2000:]


def test_a_request_with_its_origin_is_counted_as_requested_not_as_a_crash(tmp_path):
    system, _ = _start(tmp_path, """
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[Steady(component_name="solo")])
launcher.bringup()
""", crashes=0)
    try:
        wait_until(lambda: system.state("solo") == "active", timeout=30, what="solo active")
        pid = system.pid("solo")
        assert system.rpc.call("lifecycle", component="solo", request="restart", by="ui", timeout=30.0) is True
        system.wait_new_pid("solo", pid, timeout=30)
        node = _status_json(system)["worker:solo"]
        assert _restarts(node) == (1, {"requested": 1}, "requested")
        assert node["last_restart_detail"] == "restart of solo requested by ui"
    finally:
        assert system.stop() == 0
    assert _summary_line(system.output(), "solo") == "solo                     restarted after: 1 requested"


def test_counts_carry_over_when_an_escalation_restarts_the_group(tmp_path):
    system, flags = _start(tmp_path, """
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[Crashy(component_name="crashy"), Steady(component_name="bystander")], package_name="g",
                 max_restarts=1, max_seconds=60)
launcher.bringup()
""", crashes=2)
    try:
        # crash 1: restarted by its group; crash 2 breaches the group's intensity: the root
        # restarts the group, which starts both components again.
        wait_until(lambda: len(list(flags.iterdir())) == 2, timeout=60, what="two crashes")
        wait_until(lambda: any(e["event"] == "escalated" for e in system.events()), timeout=30, what="the escalation")
        wait_until(lambda: system.state("crashy") == "active" and system.state("bystander") == "active", timeout=30, what="the group back")
        wait_until(lambda: _status_json(system)["worker:bystander"]["restarts"] == 1, timeout=30, what="the group's restart counted")
        nodes = _status_json(system)
        assert _restarts(nodes["worker:crashy"]) == (2, {"crash": 1, "escalation": 1}, "escalation")
        assert _restarts(nodes["worker:bystander"]) == (1, {"escalation": 1}, "escalation")
        assert _restarts(nodes["supervisor:g"])[1:] == ({"escalated": 1}, "escalated")
    finally:
        assert system.stop() == 0
    out = system.output()
    assert _summary_line(out, "crashy") == "crashy                   restarted after: 1 crash, 1 escalation", out[-2000:]
    assert _summary_line(out, "bystander") == "bystander                restarted after: 1 escalation", out[-2000:]
    assert "group g restarted after: 1 escalated" in out


STALE = """
FLAGS = os.environ["FLAGS"]

class FailsOnGo(BaseComponent):
    '''First incarnation: healthy until the test creates FLAGS/go, then COMPONENT_FAILURE (the
    default fallback restarts it). Later incarnations take 1 s to configure and stay healthy.'''
    def custom_on_configure(self):
        seen = os.path.join(FLAGS, "seen-" + self.component_name)
        self.first = not os.path.exists(seen)
        if self.first:
            open(seen, "w").close()
        else:
            time.sleep(1.0)
    def _execution_step(self):
        if self.first and os.path.exists(os.path.join(FLAGS, "go")):
            self.health_status.set_fail_component()
        else:
            self.health_status.set_healthy()

x, y = FailsOnGo(component_name="x"), FailsOnGo(component_name="y")
for c in (x, y):
    c.config.loop_rate = 20.0
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[x, y], package_name="pair", strategy="one_for_all", max_restarts=10, max_seconds=60)
launcher.bringup()
"""


def test_the_fallbacks_do_not_restart_a_new_incarnation_for_a_failure_of_the_previous_one(tmp_path):
    """x and y fail together; each one's fallback asks for a restart. The first restarts the whole
    group (one_for_all); the second was for an incarnation that this ended, and must not restart
    the fresh group again (the old code did, as soon as the group's lock was free)."""
    flags = tmp_path / "flags"
    flags.mkdir()
    system = SystemUnderTest(tmp_path, STALE, env={"FLAGS": str(flags)}).wait_up(components=["x", "y"])
    try:
        before = {n: system.pid(n) for n in ("x", "y")}
        (flags / "go").touch()
        for n in ("x", "y"):
            system.wait_new_pid(n, before[n], timeout=60)
        wait_until(lambda: all(system.workers()[n].get("health") == "HEALTHY" for n in ("x", "y")), timeout=30, what="both healthy")
        after = {n: system.pid(n) for n in ("x", "y")}
        time.sleep(2.0)  # a quiet period: the old code's second restart came as soon as the group was up
        events = system.events()
        exits = [(e["child"], e["reason"]) for e in events if e["event"] == "exit"]
        assert len(exits) == 1 and exits[0][1] == "restart_requested", events
        assert {n: system.pid(n) for n in ("x", "y")} == after
        nodes = _status_json(system)
        assert sorted(nodes[f"worker:{n}"]["last_restart_reason"] for n in ("x", "y")) == ["fallback", "group restart"]
        assert sorted(str(nodes[f"worker:{n}"]["restart_reasons"]) for n in ("x", "y")) == ["{'fallback': 1}", "{'group restart': 1}"]
        assert nodes["worker:x"]["restarts"] == nodes["worker:y"]["restarts"] == 1
    finally:
        assert system.stop() == 0
