"""``emos robot inspect`` as a user runs it."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

pytestmark = pytest.mark.process


def test_emos_robot_inspect_command_line():
    out = subprocess.run([sys.executable, "-m", "emos", "robot", "inspect", "create2", "--json"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    info = json.loads(out.stdout)
    assert set(info) >= {"feedback", "commands", "actions", "events", "transports", "config", "robot_config"}
    text = subprocess.run([sys.executable, "-m", "emos", "robot", "inspect", "rplidar"], capture_output=True, text=True, timeout=120)
    assert text.returncode == 0 and "/scan" in text.stdout and "restart_scan" in text.stdout
    bad = subprocess.run([sys.executable, "-m", "emos", "robot", "inspect", "roomba"], capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and "unknown robot plugin 'roomba'" in bad.stderr
