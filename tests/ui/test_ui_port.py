"""A taken UI port does not stop the robot: the UI reports it and listens once the port is free."""
from __future__ import annotations

import json
import re
import socket
import subprocess
import sys
import time
import urllib.request

import pytest

from tests.ui.conftest import HERE, free_port, start_recipe, stop_recipe, token_of, wait_link

pytestmark = [pytest.mark.process, pytest.mark.timeout(120)]


def _health(run_id: str) -> dict:
    out = subprocess.run([sys.executable, "-m", "emos.tools.cli", "status", "--json", "--run", run_id],
                         capture_output=True, text=True, timeout=30)
    tree = json.loads(out.stdout)["tree"]
    return {w["name"]: w.get("health") for g in tree["children"] for w in g["children"]}


def test_taken_port_is_reported_and_retried_while_the_robot_runs(tmp_path):
    port = free_port()
    holder = socket.socket()
    holder.bind(("127.0.0.1", port))
    holder.listen()
    log = tmp_path / "recipe.log"
    proc = start_recipe(HERE / "port_recipe.py", {"EMOS_UI_TEST_PORT": str(port), "EMOS_HOME": str(tmp_path / "home")}, log)
    try:
        deadline = time.monotonic() + 60
        run_id = None
        while run_id is None and time.monotonic() < deadline:
            m = re.search(r"system up: .*\(run (\S+)\)", log.read_text())
            run_id = m.group(1) if m else None
            assert proc.poll() is None, log.read_text()
            time.sleep(0.2)
        assert run_id, log.read_text()
        token = token_of(wait_link(log, proc))  # printed at bringup, before the UI listens
        while time.monotonic() < deadline and _health(run_id).get("ui") != "SYSTEM_FAILURE":
            time.sleep(0.3)
        health = _health(run_id)
        assert health == {"talker": "HEALTHY", "ui": "SYSTEM_FAILURE"}, health
        assert f"the UI cannot listen on 127.0.0.1:{port}: Address already in use" in log.read_text()
        time.sleep(3.0)  # longer than the supervisor's failure debounce: nothing may restart the UI
        assert _health(run_id) == {"talker": "HEALTHY", "ui": "SYSTEM_FAILURE"}
        holder.close()
        while time.monotonic() < deadline:
            try:
                request = urllib.request.Request(f"http://127.0.0.1:{port}/api/layout", headers={"Authorization": f"Bearer {token}"})
                with urllib.request.urlopen(request, timeout=2) as r:
                    assert json.loads(r.read())["outputs"][0]["topic"] == "/words"
                    break
            except OSError:
                time.sleep(0.3)
        else:
            raise AssertionError("the UI never listened after the port was freed")
        while time.monotonic() < deadline and _health(run_id).get("ui") != "HEALTHY":
            time.sleep(0.3)
        assert _health(run_id)["ui"] == "HEALTHY"
    finally:
        holder.close()
        stop_recipe(proc)
