"""The chaos runner itself: it waits for the whole system, not just its first groups, before
the first fault; a fault aimed at a component the system does not have ends the run with a
clear error, the system stopped, instead of a traceback; SIGTERM keeps the finished runs'
results."""
import json
import re
import signal
import subprocess
import sys
import textwrap
import time

import psutil
import pytest

from emos.chaos.target import RunningSystem
from emos.transport.context import runtime_root

pytestmark = pytest.mark.process

# Two groups: the launcher starts them one after the other, and the second one's component
# takes seconds to activate (a model loading, a driver finding its device).
RECIPE = textwrap.dedent('''
    import time
    from emos import BaseComponent, Launcher

    class Quick(BaseComponent):
        def _execution_step(self):
            self.health_status.set_healthy()

    class Late(BaseComponent):
        def custom_on_activate(self):
            time.sleep(3.0)

        def _execution_step(self):
            self.health_status.set_healthy()

    launcher = Launcher(multi_processing=True)
    launcher.add_pkg(components=[Quick(component_name="quick", trigger=0.1)], package_name="first")
    launcher.add_pkg(components=[Late(component_name="late", trigger=0.1)], package_name="second")
    launcher.bringup()
''')


def _scenario(tmp_path, name, duration, cooldown, target):
    """The two-group recipe and a scenario killing ``target`` every second after 0.5 s."""
    (tmp_path / "two_groups.py").write_text(RECIPE)
    scenario = tmp_path / f"{name}.yaml"
    scenario.write_text(f"name: {name}\nrecipe: two_groups.py\nduration: {duration}\nwarmup: 0.5\n"
                        f"cooldown: {cooldown}\nschedule:\n  every: 1.0\n  nemeses:\n    - {{kind: kill, target: {target}}}\n")
    return scenario


def test_start_returns_only_once_every_group_is_up(tmp_path):
    recipe = tmp_path / "two_groups.py"
    recipe.write_text(RECIPE)
    system = RunningSystem(recipe, duration=60, log_path=tmp_path / "run.log")
    try:
        system.start()
        workers = system.workers()
        assert {"quick", "late"} <= set(workers), workers
        assert workers["late"]["health"] == "HEALTHY" and workers["late"].get("pid")
        assert system.tree()["up"] is True
    finally:
        if system.alive:
            system.stop()
    assert system.run_dir is not None and not system.run_dir.exists()


def test_a_fault_aimed_at_a_component_the_system_lacks_is_a_clear_error(tmp_path):
    scenario = _scenario(tmp_path, "typo", duration=20, cooldown=5, target="lat")
    proc = subprocess.run([sys.executable, "-m", "emos", "chaos", "run", str(scenario), "--json", "--no-plot",
                           "--out", str(tmp_path / "out")], capture_output=True, text=True, timeout=180)
    assert proc.returncode == 2, proc.stderr[-3000:]
    assert "Traceback" not in proc.stderr
    assert "typo.yaml, seed 1: kill: no component named 'lat'; components: late, quick" in proc.stderr
    assert "system stopped" in proc.stderr
    (log,) = (tmp_path / "out").glob("typo-*/run-1.log")
    run_id = re.search(r"system up: 2 components \(run (\S+)\)", log.read_text()).group(1)
    assert not (runtime_root() / run_id).exists()  # stopped in order: its run directory is gone


def test_sigterm_between_runs_keeps_the_finished_runs_results_and_stops_the_system(tmp_path):
    scenario = _scenario(tmp_path, "kills", duration=3, cooldown=0, target="each")
    recipe = tmp_path / "two_groups.py"
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "emos", "chaos", "run", str(scenario), "--runs", "5", "--no-plot",
                             "--out", str(out)], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    seen = []
    try:
        deadline = time.monotonic() + 150
        for line in proc.stdout:  # progress lines; the first run's verdict ends it
            seen.append(line)
            if line.startswith("[kills seed 1] pass") or line.startswith("[kills seed 1] FAIL"):
                break
            assert time.monotonic() < deadline, "".join(seen)
        proc.send_signal(signal.SIGTERM)  # during the second run
        rest, _ = proc.communicate(timeout=90)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 143, "".join(seen) + rest
    (results,) = out.glob("kills-*/results.json")
    runs = json.loads(results.read_text())["runs"]
    assert [r["seed"] for r in runs] == [1] and runs[0]["faults"] >= 1
    # The interrupted run was stopped wherever the signal found it (starting or up): no process of
    # the recipe is left, and a run that came up has its directory removed.
    assert not [p.pid for p in psutil.process_iter(["cmdline"]) if str(recipe) in " ".join(p.info["cmdline"] or [])]
    for log in out.glob("kills-*/run-*.log"):
        up = re.search(r"system up: 2 components \(run (\S+)\)", log.read_text())
        assert up is None or not (runtime_root() / up.group(1)).exists(), log


def test_emos_status_says_when_later_groups_are_still_starting():
    from emos.tools.cli.status import render

    answer = {"run_id": "r1", "pid": 7, "uptime_s": 1.5,
              "tree": {"name": "root", "kind": "supervisor", "strategy": "one_for_one", "children": [
                  {"name": "first", "kind": "supervisor", "strategy": "one_for_one", "children": [
                      {"name": "quick", "kind": "worker", "pid": 8, "state": "active", "health": "HEALTHY"}]}]}}
    assert "starting" not in render({**answer, "up": True})
    assert "starting" not in render(answer)  # a supervisor from before the key: says nothing
    text = render({**answer, "up": False})
    assert "(starting: later groups are not up yet)" in text.splitlines()[0] and "quick" in text
