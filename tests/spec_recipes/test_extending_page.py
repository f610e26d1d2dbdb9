"""The extending page's custom component and recipe (recipes/extending/) run with ``emos run``:
the component runs in a process of its own with its config class, its timed step keeps it
healthy, and the low-battery event logs its message."""
from __future__ import annotations

import shutil
import sys
import time

import pytest

from emos import msgs as M
from tests.agents.components_helpers import Probe
from tests.runtime.helpers import REPO, SystemUnderTest, wait_until

pytestmark = pytest.mark.process

PAGE = REPO / "recipes" / "extending"


def test_awesome_config_validates_its_fields():
    sys.path.insert(0, str(PAGE))
    try:
        from my_awesome_pkg.awesome_component import AwesomeComponent, AwesomeConfig
    finally:
        sys.path.remove(str(PAGE))
    assert AwesomeConfig().extra_float == 10.0 and AwesomeConfig().extra_flag is True
    with pytest.raises(ValueError, match="extra_float"):
        AwesomeConfig(extra_float=0.0)  # outside in_range(1e-9, 1e9)
    assert AwesomeComponent(component_name="c", config=AwesomeConfig(extra_float=2.0)).config.extra_float == 2.0


def test_awesome_recipe_runs_the_component_apart_and_logs_low_battery(tmp_path):
    shutil.copytree(PAGE / "my_awesome_pkg", tmp_path / "my_awesome_pkg")
    system = SystemUnderTest(tmp_path, (PAGE / "awesome_recipe.py").read_text(), duration=120)
    probe = None
    try:
        system.wait_up(components=["awesome_component"], timeout=90)
        assert system.pid("awesome_component") not in (None, system.proc.pid)  # multiprocessing=True
        probe = Probe(system)
        status = probe.status("awesome_component")
        assert status.status == M.ComponentStatus.STATUS_HEALTHY, status  # the step ran: set_healthy()
        wait_until(lambda: "watching 1 events" in system.output(), 30, what="the monitor")
        probe.pub("/battery_level", M.Float32(data=50.0))
        probe.pub("/battery_level", M.Float32(data=12.0))
        wait_until(lambda: "Battery is Low!" in system.output(), 30, what="the low-battery log line")
        time.sleep(1.0)
        assert system.output().count("Battery is Low!") == 1, system.output()[-3000:]
    finally:
        if probe is not None:
            probe.close()
        assert system.stop() == 0, system.output()[-3000:]


def test_the_packages_executable_runs_one_component_and_refuses_an_unknown_one(tmp_path):
    """Step 5's executable.py (ros_sugar.executable_main, ported as emos.executable_main) is not
    needed by EMOS, but a package that keeps it can start one component with it."""
    import os
    import subprocess

    env = {**os.environ, "PYTHONPATH": str(PAGE) + os.pathsep + str(REPO)}
    cmd = [sys.executable, "-m", "my_awesome_pkg.executable"]
    bad = subprocess.run([*cmd, "--component_type", "Nope"], env=env, cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and "'Nope' is not one of this package's components: AwesomeComponent" in bad.stderr, bad.stderr
    ran = subprocess.run([*cmd, "--component_type", "AwesomeComponent", "--component_name", "awesome", "--duration", "3"],
                         env=env, cwd=tmp_path, capture_output=True, text=True, timeout=240)
    assert ran.returncode == 0, ran.stdout[-2000:] + ran.stderr[-2000:]
    assert "awesome started" in ran.stdout + ran.stderr
