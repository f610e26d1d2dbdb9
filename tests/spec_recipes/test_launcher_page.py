"""The launcher page's recipe (recipes/concepts/launcher_page.py, concepts/launcher.md) run with
``emos run``: the two components run in processes of their own, the configuration file is
applied, and the low-battery event logs its warning only when the battery is low."""
from __future__ import annotations

import shutil
import subprocess
import sys
import time

import pytest

from emos import msgs as M
from tests.agents.components_helpers import Probe
from tests.runtime.helpers import REPO, SystemUnderTest, wait_until

pytestmark = pytest.mark.process

PAGE = REPO / "recipes" / "concepts"
WARNING = "WARNING: Battery Low!"


def test_launcher_page_recipe_runs_its_components_apart_and_logs_low_battery(tmp_path):
    # The page's config path is relative ('config/robot_params.toml'): the run starts in tmp_path.
    shutil.copytree(PAGE / "config", tmp_path / "config")
    system = SystemUnderTest(tmp_path, (PAGE / "launcher_page.py").read_text(), duration=120)
    probe = None
    try:
        system.wait_up(components=["lidar_driver", "path_planner"], timeout=90)
        pids = {system.pid("lidar_driver"), system.pid("path_planner"), system.proc.pid}
        assert len(pids) == 3, system.tree()  # multi_processing=True: a process each

        info = subprocess.run([sys.executable, "-m", "emos", "component", "info", "--run", system.ctx.run_id,
                               "lidar_driver"], capture_output=True, text=True, timeout=60)
        assert info.returncode == 0, info.stderr
        # from robot_params.toml: its lidar_driver section, and "/**" for every component
        assert '"loop_rate": 5.0' in info.stdout and '"fallback_rate": 10.0' in info.stdout, info.stdout

        probe = Probe(system)
        for _ in range(3):  # well above the threshold of 15: no warning
            probe.pub("/battery", M.Float32(data=80.0))
            time.sleep(0.1)
        wait_until(lambda: "watching 1 events" in system.output(), 30, what="the monitor")
        probe.pub("/battery", M.Float32(data=12.0))
        wait_until(lambda: WARNING in system.output(), 30, what=f"{WARNING!r} in the log")
        time.sleep(1.0)  # let any late firing show
        assert system.output().count(WARNING) == 1, system.output()[-3000:]  # the low reading only, once
    finally:
        if probe is not None:
            probe.close()
        assert system.stop() == 0, system.output()[-3000:]
