"""Issue 9, probe 5: every process a component creates dies with it and is reaped."""
import os
import signal
import time

import psutil
import pytest

from tests.runtime.helpers import HANG_S, SystemUnderTest, wait_until

pytestmark = pytest.mark.process

FORKER = """
import subprocess

class Forker(BaseComponent):
    '''Starts N_CHILDREN `sleep 3600` (one escapes its process group with setsid) and records their pids.'''
    def custom_on_activate(self):
        kids = [subprocess.Popen(["sleep", "3600"]) for _ in range(2)]
        kids.append(subprocess.Popen(["sleep", "3600"], start_new_session=True))
        with open(os.environ["PID_LOG"], "a") as f:
            for k in kids:
                f.write(f"{k.pid}\\n")
    def _execution_step(self):
        self.health_status.set_healthy()
"""


def _logged_pids(path) -> list[int]:
    return [int(x) for x in path.read_text().split()] if path.exists() else []


def _alive(pid: int) -> bool:
    try:
        return psutil.Process(pid).status() != psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return False


def _zombie_children(pid: int) -> list[int]:
    try:
        return [c.pid for c in psutil.Process(pid).children() if c.status() == psutil.STATUS_ZOMBIE]
    except psutil.NoSuchProcess:
        return []


def test_children_of_a_killed_component_die_with_it_and_are_reaped(tmp_path):
    pid_log = tmp_path / "pids"
    system = SystemUnderTest(tmp_path, FORKER + """
c = Forker(component_name="forker")
c.config.loop_rate = 20.0
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[c])
launcher.bringup()
""", env={"PID_LOG": str(pid_log)}).wait_up(components=["forker"])
    try:
        first = wait_until(lambda: len(_logged_pids(pid_log)) == 3 and _logged_pids(pid_log), what="3 children")
        old = system.pid("forker")
        os.kill(old, signal.SIGKILL)
        system.wait_new_pid("forker", old)
        # The three children of the dead incarnation (the setsid one included) die and are reaped.
        wait_until(lambda: not any(_alive(p) for p in first), timeout=HANG_S, what="the dead component's children to die")
        wait_until(lambda: _zombie_children(system.proc.pid) == [], timeout=HANG_S, what="no zombies under the launcher")
        wait_until(lambda: len(_logged_pids(pid_log)) == 6, what="the new incarnation's children")
        second = _logged_pids(pid_log)[3:]
        assert all(_alive(p) for p in second)
    finally:
        assert system.stop() == 0
    # Stopping the system takes the live incarnation's children too.
    wait_until(lambda: not any(_alive(p) for p in second), timeout=HANG_S, what="children to die with the system")
    assert system.leftovers() == []


def test_a_component_crashing_repeatedly_leaves_no_zombies_or_children(tmp_path):
    pid_log = tmp_path / "pids"
    system = SystemUnderTest(tmp_path, """
import subprocess

class Crasher(BaseComponent):
    def custom_on_activate(self):
        k = subprocess.Popen(["sleep", "3600"])
        with open(os.environ["PID_LOG"], "a") as f:
            f.write(f"{k.pid}\\n")
        self.t0 = time.monotonic()
    def _execution_step(self):
        if time.monotonic() - self.t0 > 0.2:
            os._exit(3)

c = Crasher(component_name="crasher")
c.config.loop_rate = 20.0
launcher = Launcher(multi_processing=True, max_restarts=100, max_seconds=1.0)
launcher.add_pkg(components=[c])
launcher.bringup()
""", env={"PID_LOG": str(pid_log)}).wait_up()
    try:
        wait_until(lambda: len(_logged_pids(pid_log)) >= 5, timeout=20, what="5 crashes")
        time.sleep(0.3)
        pids = _logged_pids(pid_log)
        # All but the newest incarnation's child are gone, and nothing waits to be reaped.
        wait_until(lambda: sum(_alive(p) for p in pids) <= 1, timeout=HANG_S, what="children of crashed incarnations to die")
        wait_until(lambda: len(_zombie_children(system.proc.pid)) <= 1, timeout=HANG_S, what="zombies reaped")
    finally:
        assert system.stop() == 0
    assert not any(_alive(p) for p in _logged_pids(pid_log))
    assert system.leftovers() == []


def test_killing_the_launcher_takes_the_components_children_too(tmp_path):
    pid_log = tmp_path / "pids"
    system = SystemUnderTest(tmp_path, FORKER + """
c = Forker(component_name="forker")
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[c])
launcher.bringup()
""", env={"PID_LOG": str(pid_log)}).wait_up(components=["forker"])
    pids = wait_until(lambda: len(_logged_pids(pid_log)) == 3 and _logged_pids(pid_log), what="3 children")
    system.kill_all()
    wait_until(lambda: not any(_alive(p) for p in pids), timeout=HANG_S, what="children to die with the launcher")


def test_children_of_threaded_components_die_with_the_run(tmp_path):
    pid_log = tmp_path / "pids"
    system = SystemUnderTest(tmp_path, FORKER + """
c = Forker(component_name="forker")
launcher = Launcher(multi_processing=False)
launcher.add_pkg(components=[c])
launcher.bringup()
""", env={"PID_LOG": str(pid_log)}).wait_up(components=["forker"])
    try:
        pids = wait_until(lambda: len(_logged_pids(pid_log)) == 3 and _logged_pids(pid_log), what="3 children")
    finally:
        assert system.stop() == 0
    wait_until(lambda: not any(_alive(p) for p in pids), timeout=HANG_S, what="the threaded component's children to die with the run")
