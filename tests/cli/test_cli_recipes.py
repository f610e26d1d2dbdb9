"""`emos ls | info | run NAME | logs | service | version`, as a user runs them (subprocesses)."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

pytestmark = pytest.mark.process

ROOT = Path(__file__).resolve().parents[2]

RECIPE = textwrap.dedent('''
    """Counts, for the CLI tests."""
    from pathlib import Path
    from emos import BaseComponent, Launcher, Topic

    Path(__file__).with_name("ran.marker").touch()
    scan = Topic(name="scan", msg_type="LaserScan")
    image = Topic(name="camera/rgb", msg_type="Image")
    SPEECH = "speech"
    words = Topic(name=SPEECH, msg_type="String")
    launcher = Launcher(multi_processing=True)
    launcher.add_pkg(components=[BaseComponent(component_name="ticker", inputs=[scan, image], outputs=[words], trigger=0.1)])
    print("recipe says hello", flush=True)
    launcher.bringup()
''')


@pytest.fixture
def home(tmp_path, monkeypatch):
    home = tmp_path / "emos_home"
    folder = home / "recipes" / "counter"
    folder.mkdir(parents=True)
    (folder / "recipe.py").write_text(RECIPE)
    (folder / "manifest.json").write_text(json.dumps({"name": "Counter", "description": "counts ticks"}))
    monkeypatch.setenv("EMOS_HOME", str(home))
    return home


def emos(*args: str, timeout: float = 60) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "emos.tools.cli", *args], capture_output=True, text=True, timeout=timeout,
                          cwd=ROOT, env=dict(os.environ))


def test_ls_lists_user_and_project_recipes(home):
    out = emos("ls")
    assert out.returncode == 0, out.stderr
    assert "counter" in out.stdout and "Counter: counts ticks" in out.stdout
    assert "ui_demo" in out.stdout and "sensor_demo" in out.stdout
    listed = {r["name"]: r for r in json.loads(emos("ls", "--json").stdout)}
    assert listed["counter"]["source"] == "user" and listed["ui_demo"]["source"] == "project"


def test_info_reads_the_source_without_running_it(home):
    out = emos("info", "counter")
    assert out.returncode == 0, out.stderr
    sensors = out.stdout.split("required sensors:")[1].split("other topics:")[0]
    assert "scan" in sensors and "LaserScan" in sensors and "2D lidar" in sensors and "camera/rgb" in sensors
    others = out.stdout.split("other topics:")[1]
    assert "speech" in others and "String" in others  # the name came through a variable
    assert not (home / "recipes" / "counter" / "ran.marker").exists()


def test_info_on_a_syntax_error_names_the_line_and_runs_nothing(tmp_path, home):
    bad = tmp_path / "bad.py"
    bad.write_text('from pathlib import Path\nPath("ran").touch()\nx = Topic(name="a", msg_type="String"\nprint(1)\n')
    out = emos("info", str(bad))
    assert out.returncode == 2
    assert f"{bad}:3" in out.stderr and "syntax error" in out.stderr and "nothing was run" in out.stderr
    assert not (ROOT / "ran").exists()
    missing = emos("info", "no_such_recipe")
    assert missing.returncode == 2 and "no recipe 'no_such_recipe'" in missing.stderr and "counter" in missing.stderr


def test_run_by_name_keeps_a_log_that_logs_lists_and_prints(home):
    out = emos("run", "counter", "--duration", "1.5", timeout=90)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "recipe says hello" in out.stdout  # the terminal still gets everything
    assert (home / "recipes" / "counter" / "ran.marker").exists()
    listing = emos("logs")
    assert listing.returncode == 0 and "counter_" in listing.stdout
    shown = emos("logs", "counter")
    assert "recipe says hello" in shown.stdout and "bringup ended (exit code 0)" in shown.stdout
    assert "# emos run run counter" in shown.stdout or "# emos run" in shown.stdout
    assert emos("logs", "nothing_like_it").returncode == 2


def test_service_unit_is_written_printed_and_removed(home, tmp_path):
    units = tmp_path / "units"
    printed = emos("service", "create", "counter", "--print", "--restart-time", "5s")
    assert printed.returncode == 0
    unit = printed.stdout
    assert "Restart=on-failure" in unit and "RestartSec=5s" in unit and "KillMode=mixed" in unit
    assert f"run {home / 'recipes' / 'counter' / 'recipe.py'}" in unit and f"EMOS_HOME={home}" in unit
    created = emos("service", "create", "counter", "--name", "robot.service", "--install-path", str(units), "--no-enable")
    assert created.returncode == 0, created.stderr
    assert (units / "robot.service").read_text() == unit.replace("RestartSec=5s", "RestartSec=3s")
    assert "present" in emos("service", "status", "counter", "--name", "robot", "--install-path", str(units)).stdout
    assert emos("service", "remove", "counter", "--name", "robot", "--install-path", str(units)).returncode == 0
    assert not (units / "robot.service").exists()
    bad = emos("service", "create", "counter", "--restart-time", "soon")
    assert bad.returncode == 2 and "--restart-time" in bad.stderr


def test_version_and_every_command_has_help_with_an_example():
    version = emos("version")
    assert version.returncode == 0 and version.stdout.startswith("emos 0.")
    for command in ("ls", "info", "logs", "service", "version", "run", "status", "topic"):
        out = emos(command, "--help")
        assert out.returncode == 0 and "example" in out.stdout, command


def test_bench_plot_saves_the_main_result_and_checks_the_file_name_first(tmp_path):
    picture = tmp_path / "restart.png"
    out = emos("bench", "restart", "--kills", "3", "--plot", str(picture), timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr
    assert picture.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    bad = emos("bench", "restart", "--kills", "3", "--plot", str(tmp_path / "x.gif"))
    assert bad.returncode != 0 and "must end in .png, .svg or .pdf" in bad.stderr


def test_run_logs_survive_runs_started_at_the_same_moment(home, tmp_path):
    """Two `emos run` starting together (`emos bench barn --jobs 2` does): one prunes a log while
    the other lists them, and both want the same name in the same second. Neither may fail."""
    import subprocess
    import sys

    from emos.supervisor import runlog

    logs = home / "logs"
    logs.mkdir(parents=True)
    (logs / "old_20200101-000000.log").write_text("kept\n")
    (logs / "vanished_20200101-000000.log").symlink_to(tmp_path / "gone.log")  # listed, then gone
    assert [p.name for p in runlog.list_logs()] == ["old_20200101-000000.log"]
    # The same name in the same second: the second run gets ~2, not an error (and no log lost).
    code = """
import sys, time
from pathlib import Path
from emos.supervisor import runlog
time.strftime = lambda fmt, *a: "20261124-120000" if "%H" in fmt else "2026-11-24 12:00:00"
path = runlog.start_run_log(Path(sys.argv[1]), ["run", "x"])
print("LOG", path, file=sys.stderr)
"""
    recipe = home / "recipes" / "counter" / "recipe.py"
    names = []
    for _ in range(2):
        out = subprocess.run([sys.executable, "-c", code, str(recipe)], capture_output=True, text=True, timeout=60)
        assert out.returncode == 0 and "not keeping a log" not in out.stderr, out.stderr
        names.append(out.stderr.split("LOG ")[1].split()[0].rsplit("/", 1)[1])
    assert names == ["counter_20261124-120000.log", "counter_20261124-120000~2.log"]
