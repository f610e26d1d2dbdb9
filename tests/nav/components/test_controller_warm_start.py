"""The Controller imports what its followers need while it is configured, not in its first
control step: that step judges its inputs' ages by the clock after the work it did, and an import
of seconds on a busy machine made /odom look stale there (a SYSTEM failure, a restart, and the new
process imported it in its first step again: tests/runtime/test_events_recipes_real.py's
fallback recipe restarted the controller in a loop with the cores kept busy)."""
from __future__ import annotations

import subprocess
import sys

import pytest

from tests.runtime.helpers import REPO

pytestmark = pytest.mark.process  # a fresh interpreter: what this process imported already says nothing

PROBE = """
import sys
from emos.actors.nav.components import Controller, ControllerConfig
from emos.testing import ComponentHarness

controller = Controller(component_name="controller", config=ControllerConfig(algorithm="DWA"))
with ComponentHarness(controller, activate=False):  # configured only: no step has run
    print("k-d tree imported at configure:", "scipy.spatial" in sys.modules)
"""


def test_the_followers_k_d_tree_is_imported_at_configure_not_in_the_first_step():
    pytest.importorskip("scipy.spatial")
    done = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, cwd=REPO, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "k-d tree imported at configure: True" in done.stdout, done.stdout + done.stderr[-3000:]
