"""The ported "Events & Resilience" recipes run end to end and do what their pages say (the
three on the navigation stack: tests/nav/components/test_events_recipes.py)."""
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


def test_fallback_recipes():
    out = run_recipe("fallback_recipes.py", 4)
    assert "switched to model client 'local_backup_client'" in out
    assert "answered: [local backup]" in out
    # controller ladder: restart once, then switch algorithm; driver restarted on system failure
    assert "handler=on_algorithm_fail action=restart(controller) step=1" in out
    assert "algorithm switched to PurePursuit" in out
    assert "handler=on_system_fail action=restart(drive_manager)" in out


def test_event_driven_cognition_describes_on_appearance_with_debounce():
    out = run_recipe("event_driven_cognition.py", 7.5)
    assert out.count("[visual_describer] A person has been detected") == 2, out[-3000:]




def test_composed_events():
    out = run_recipe("composed_events.py", 5)
    assert out.count("EMERGENCY STOP (smart stop)") == 1  # fast near the obstacle, not slow near it
    assert out.count("EVENT describe person (battery ok)") == 1
    assert out.count("EVENT auto-track person (not in manual mode)") == 1
    assert out.count("EVENT collision (lidar or bumper)") == 1
