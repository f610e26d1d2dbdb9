"""Issue 9, probe 6: status published by someone else does not mask a component's hang."""
import subprocess
import sys

import pytest

from tests.runtime.helpers import HANG_S, SystemUnderTest, wait_until

pytestmark = pytest.mark.process

HANGER = """
class Hanger(BaseComponent):
    '''Healthy until the test says hang (the HANG_NOW file), then blocks its event loop for good, once.'''
    def _execution_step(self):
        self.health_status.set_healthy()
        if os.path.exists(os.environ["HANG_NOW"]) and not os.path.exists(os.environ["HUNG_ONCE"]):
            open(os.environ["HUNG_ONCE"], "w").close()
            time.sleep(3600)

c = Hanger(component_name="hanger")
c.config.loop_rate = 20.0
launcher = Launcher(multi_processing=MULTI, heartbeat_timeout=0.5)
launcher.add_pkg(components=[c])
launcher.bringup()
"""


def _run(tmp_path, multi: bool) -> None:
    flag, trigger = tmp_path / "hung", tmp_path / "hang-now"
    system = SystemUnderTest(tmp_path, HANGER.replace("MULTI", str(multi)),
                             env={"HUNG_ONCE": str(flag), "HANG_NOW": str(trigger)}).wait_up(components=["hanger"])
    forger = subprocess.Popen(
        [sys.executable, "-m", "emos", "topic", "pub", "/hanger/status", "ComponentStatus",
         '{"status": 0, "lifecycle_state": "active"}', "--rate", "20", "--count", "0", "--run", system.run_dir.name],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
    )
    try:
        # The hang starts only once the forged stream reaches the supervisor (a loaded machine
        # can take seconds to start the forger): a hang before it would mask nothing.
        wait_until(lambda: "does not count as its heartbeat" in system.output(), timeout=HANG_S,
                   what="the supervisor to see the forged status")
        trigger.touch()
        wait_until(flag.exists, timeout=HANG_S, what="the component to hang")
        # Detected while the forger still publishes on its status topic.
        wait_until(lambda: any(e["event"] == "exit" and e["child"] == "hanger" and e["reason"] == "hang" for e in system.events()),
                   timeout=HANG_S, what="the hang to be detected")
        assert forger.poll() is None, forger.stderr.read()
        wait_until(lambda: system.state("hanger") == "active", timeout=HANG_S, what="a fresh hanger")
    finally:
        forger.terminate()
        forger.wait(10)
        assert system.stop() == 0


def test_a_forged_status_stream_does_not_mask_a_hung_process(tmp_path):
    _run(tmp_path, multi=True)


def test_a_forged_status_stream_does_not_mask_a_hung_thread(tmp_path):
    _run(tmp_path, multi=False)
