"""Issue 31 item 10: `emos service create` writes a root unit, so nothing typed may change its meaning.

The units go to a temporary --install-path (never /etc/systemd); each is read back here with a
parser of this file's own (shlex for systemd's quoting, then systemd's `%%` and `$$` rules), and
checked by `systemd-analyze verify` where it is installed.
"""
from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.process

ROOT = Path(__file__).resolve().parents[2]
RECIPE = "from emos import Launcher\nLauncher().bringup()\n"
HAS_ANALYZE = shutil.which("systemd-analyze") is not None


def emos(*args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "emos.tools.cli", *args], check=False, capture_output=True, text=True, timeout=120,
                          cwd=ROOT, env={**os.environ, **(env or {})})


def recipe_in(folder: Path) -> Path:
    folder.mkdir(parents=True)
    path = folder / "patrol.py"
    path.write_text(RECIPE)
    return path


def unit_values(text: str, key: str) -> list[str]:
    return [line.split("=", 1)[1] for line in text.splitlines() if line.startswith(f"{key}=")]


def unspecify(word: str) -> str:
    assert not re.search(r"(?<!%)%(%%)*(?!%)", word), f"a lone % systemd would expand in {word!r}"
    return word.replace("%%", "%")


def exec_argv(text: str) -> list[str]:
    """ExecStart= as the process will see it: unquoted, specifiers and $-variables resolved."""
    (line,) = unit_values(text, "ExecStart")
    words = [unspecify(w) for w in shlex.split(line, posix=True)]
    for word in words[1:]:
        assert all(len(run) % 2 == 0 for run in re.findall(r"\$+", word)), f"a lone $ systemd would expand in {word!r}"
    return words[:1] + [w.replace("$$", "$") for w in words[1:]]


def environment(text: str) -> dict[str, str]:
    env = {}
    for line in unit_values(text, "Environment"):
        for word in shlex.split(line, posix=True):
            key, _, value = unspecify(word).partition("=")
            env[key] = value
    return env


@pytest.mark.parametrize("option,value", [("--service-description", "robot\nExecStartPre=/bin/touch /tmp/owned"),
                                          ("--user", "root\nExecStartPre=/bin/touch /tmp/owned"),
                                          ("--service-description", "tab\there")])
def test_a_control_character_in_a_value_is_refused_naming_the_option(tmp_path, option, value):
    recipe = recipe_in(tmp_path / "r")
    units = tmp_path / "units"
    out = emos("service", "create", str(recipe), "--install-path", str(units), "--no-enable", option, value)
    assert out.returncode == 2, out.stdout + out.stderr
    assert f"{option} must not contain control characters" in out.stderr
    assert "Traceback" not in out.stderr
    assert not units.exists() or list(units.iterdir()) == []


def test_user_must_be_an_existing_plain_user_name(tmp_path):
    recipe = recipe_in(tmp_path / "r")
    missing = emos("service", "create", str(recipe), "--print", "--user", "no_such_user_31")
    assert missing.returncode == 2 and "--user 'no_such_user_31': no such user" in missing.stderr
    odd = emos("service", "create", str(recipe), "--print", "--user", "root %n")
    assert odd.returncode == 2 and "--user must be a user name" in odd.stderr
    fine = emos("service", "create", str(recipe), "--print", "--user", "root")
    assert fine.returncode == 0, fine.stderr
    assert unit_values(fine.stdout, "User") == ["root"]


def test_percent_dollar_quotes_and_spaces_in_the_recipe_path_reach_the_service_unchanged(tmp_path):
    recipe = recipe_in(tmp_path / "robot 50% $HOME ${X} \"it's\" ;")
    units = tmp_path / "units"
    out = emos("service", "create", str(recipe), "--name", "patrol", "--install-path", str(units), "--no-enable",
               "--service-description", "patrol at 100% of $speed")
    assert out.returncode == 0, out.stdout + out.stderr
    assert "wrote" in out.stdout
    text = (units / "patrol.service").read_text()
    assert exec_argv(text) == [sys.executable, "-m", "emos", "run", str(recipe.resolve())]
    assert unspecify(unit_values(text, "WorkingDirectory")[0]) == str(recipe.resolve().parent)
    assert unspecify(unit_values(text, "Description")[0]) == "patrol at 100% of $speed"
    if HAS_ANALYZE:
        assert "checked by systemd-analyze verify" in out.stdout
        verify = subprocess.run(["systemd-analyze", "verify", "--man=no", str(units / "patrol.service")], check=False, capture_output=True, text=True, timeout=60)
        assert verify.returncode == 0 and str(units) not in verify.stderr, verify.stderr


def test_emos_home_with_a_space_is_kept_whole_and_quoted(tmp_path):
    recipe = recipe_in(tmp_path / "r")
    home = tmp_path / "my emos home %i"
    out = emos("service", "create", str(recipe), "--print", env={"EMOS_HOME": str(home)})
    assert out.returncode == 0, out.stderr
    assert f'Environment="EMOS_HOME={str(home).replace("%", "%%")}"' in out.stdout
    assert environment(out.stdout) == {"PYTHONUNBUFFERED": "1", "EMOS_HOME": str(home)}


def test_without_systemd_analyze_the_unit_is_checked_by_the_built_in_reader_and_says_so(tmp_path):
    recipe = recipe_in(tmp_path / "r x")
    units = tmp_path / "units"
    out = emos("service", "create", str(recipe), "--install-path", str(units), "--no-enable", env={"PATH": str(tmp_path / "empty")})
    assert out.returncode == 0, out.stderr
    assert "built-in reader (systemd-analyze is not installed: systemd's own check was skipped)" in out.stdout
    assert exec_argv((units / "emos-patrol.service").read_text())[-1] == str(recipe.resolve())


@pytest.mark.skipif(not HAS_ANALYZE, reason="needs systemd-analyze")
def test_a_unit_systemd_rejects_is_not_reported_as_created_and_the_old_one_stays(tmp_path):
    recipe = recipe_in(tmp_path / "r")
    units = tmp_path / "units"
    # Passes our pattern for a duration, but overflows systemd's: it would silently drop RestartSec.
    out = emos("service", "create", str(recipe), "--install-path", str(units), "--no-enable", "--restart-time", "99999999999999999999999h")
    assert out.returncode == 1, out.stdout + out.stderr
    assert "wrote" not in out.stdout and "systemd-analyze verify rejects the unit" in out.stderr
    assert "Failed to parse" in out.stderr and "it was removed again" in out.stderr
    assert not (units / "emos-patrol.service").exists()
    good = emos("service", "create", str(recipe), "--install-path", str(units), "--no-enable")
    assert good.returncode == 0, good.stderr
    before = (units / "emos-patrol.service").read_text()
    again = emos("service", "create", str(recipe), "--install-path", str(units), "--no-enable", "--restart-time", "99999999999999999999999h")
    assert again.returncode == 1 and "the unit that was there before is back in place" in again.stderr
    assert (units / "emos-patrol.service").read_text() == before
