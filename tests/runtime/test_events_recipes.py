"""The ported "Events & Resilience" recipes run end to end and do what their pages say."""
import subprocess
import sys

import pytest

from tests.runtime.helpers import REPO

RECIPES = REPO / "recipes" / "events_and_resilience"


def run_recipe(name: str, duration: float) -> str:
    proc = subprocess.run([sys.executable, "-m", "emos", "run", str(RECIPES / name), "--duration", str(duration)],
                          capture_output=True, text=True, timeout=120, cwd=str(REPO))
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out[-4000:]
    assert "Traceback" not in out, out[-4000:]
    return out


def test_external_reflexes_switch_algorithm_then_send_the_goal():
    out = run_recipe("external_reflexes.py", 4)
    assert "[controller] following 'person' with VisionRGBDFollower" in out


def test_cross_component_events():
    out = run_recipe("cross_component_events.py", 5)
    assert out.count("[drive_manager] unblocking") == 1
    assert out.count("direct sensor mode: on") == 1
    assert "Got new goal point" in out and "[planner] planning to (2.00, 0.50) within 0.05 m" in out


def test_context_aware_actions_inject_topic_data():
    out = run_recipe("context_aware_actions.py", 6)
    assert "navigating to kitchen at (2.0, 0.5)" in out
    assert "Unknown location: garage" in out
    assert "[planner] new goal in map: (2.0, 0.5)" in out
    assert "VLM prompt: A chair has been detected" in out
