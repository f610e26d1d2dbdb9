"""The three "Events & Resilience" recipes ported to the real components, end to end under
``emos run``: fallback_recipes (LLM with two real model servers, Controller and DriveManager on
the Simulator), event_driven_cognition (Vision on the Simulator's camera wakes the VLM) and
composed_events (the smart stop acts in the DriveManager on the Simulator's odometry and scan).
They assert what happened, where and in which order; never how fast."""
from __future__ import annotations

import re
import time

import pytest

from tests.agents.components_helpers import Probe
from tests.agents.fixtures.server_process import start_server
from tests.runtime.helpers import REPO, SystemUnderTest, kill_leftover_systems, wait_until

pytestmark = pytest.mark.process

RECIPES = REPO / "recipes" / "events_and_resilience"
RESPONDER = str(REPO / "recipes" / "models" / "responder.yaml")


@pytest.fixture(autouse=True)
def _no_system_outlives_its_test():
    yield
    kill_leftover_systems()


@pytest.fixture
def backup_server():
    server = start_server(script=RESPONDER)
    yield server
    server.stop()


def _run(tmp_path, recipe: str, env: dict, duration: float = 1100) -> SystemUnderTest:
    """``duration`` (wall s) only bounds a hang, past every wait of the tests, which stop the run
    themselves: a run capped at 120 s ended before the fallback recipe's controller ladder on a
    busy machine, and no longer wait could then see it."""
    return SystemUnderTest(tmp_path, (RECIPES / recipe).read_text(), duration=duration,
                           env={"HOME": str(tmp_path), **env})


def _line(out: str, pattern: str, after: int = 0) -> int:
    """Position of the first match of ``pattern`` at or after ``after`` (-1: none)."""
    m = re.compile(pattern).search(out, after)
    return m.start() if m else -1


# The waits below are for events in the order the ladders promise; their timeouts only bound a
# hang, and are long because a busy machine runs the simulated house slower than real time.
@pytest.mark.timeout(1200)
def test_fallback_recipes_model_server_loss_and_navigation_ladders(tmp_path, backup_server):
    primary = start_server(script=RESPONDER)
    system = _run(tmp_path, "fallback_recipes.py",
                  {"EMOS_MODELS_PORT": str(backup_server.port), "EMOS_PRIMARY_PORT": str(primary.port)})
    try:
        system.wait_up(components=["sim", "route", "user", "brain", "controller", "drive_manager"], timeout=240)
        out = system.output
        # 1. The primary (RoboML) answers while it runs.
        wait_until(lambda: "[user] the brain answered" in out(), 240, interval=0.2, what="an answer from the primary")
        assert "model client is now" not in out()
        # 2. The primary server dies: the brain's ladder swaps to the backup and answers go on.
        #    (The log position is taken before the stop: the swap can come while a busy machine
        #    is still shutting the server down.)
        killed = len(out())
        primary.stop()

        def answered_after_swap() -> bool:
            text = out()
            swap = _line(text, r"model client is now 'local_backup_client'", killed)
            return swap > 0 and _line(text, r"\[user\] the brain answered", swap) > 0

        wait_until(answered_after_swap, 240, interval=0.2, what="an answer after the swap to the backup")
        text = out()
        assert _line(text, r"\[brain\] fallback handler=on_(component|algorithm)_fail action=brain\.change_model_client\(\)", killed) > 0, text[killed:][-3000:]
        # 3. The controller's ladder, in order: DWA stalls at the closed door -> restart ->
        #    DWA stalls again -> switch to PurePursuit (in the running controller) -> it stalls
        #    too -> ladder spent.
        gave_up = r"\[controller\] gave_up handler=on_algorithm_fail"
        wait_until(lambda: _line(out(), gave_up) > 0, 480, interval=0.2, what="the controller's ladder spent")
        text = out()
        steps = [r"\[controller\] DWA: no progress",
                 r"\[controller\] fallback handler=on_algorithm_fail action=restart\(controller\) step=1",
                 r"\[controller\] DWA: no progress",
                 r"\[controller\] fallback handler=on_algorithm_fail action=controller\.set_algorithm\(\) step=2",
                 r"\[controller\] algorithm switched from DWA to PurePursuit",
                 r"\[controller\] PurePursuit: no progress",
                 gave_up]
        at = 0
        for step in steps:
            found = _line(text, step, at)
            assert found >= 0, f"{step!r} missing after position {at}:\n{text[-4000:]}"
            at = found + 1
        # 4. The DriveManager: the controller's restart took its command source away (a SYSTEM
        #    failure naming /control), and its on_system_fail ladder restarted it.
        # Its reason is "died" once the controller's process is gone; a machine too loaded to end
        # that process within the command timeout of its last command makes it a timeout first.
        dead = _line(text, r"\[drive_manager\] robot stopped: (the process that published the last command on /control died"
                           r"|no command for [0-9.]+ s \(cmd_timeout)")
        assert dead > 0, text[-4000:]
        assert _line(text, r"\[drive_manager\] fallback handler=on_system_fail action=restart\(drive_manager\)", dead) > 0, text[-4000:]
        assert system.state("drive_manager") == "active" and system.state("brain") == "active"
    finally:
        primary.stop()
        assert system.stop() == 0


def test_event_driven_cognition_describes_each_appearance_only(tmp_path, backup_server):
    system = _run(tmp_path, "event_driven_cognition.py", {"EMOS_MODELS_PORT": str(backup_server.port)})
    probe = Probe(system)
    try:
        system.wait_up(components=["sim", "eye_detector", "visual_describer", "narrator"], timeout=90)
        dets, descriptions = probe.sub("/detections", "Detections"), probe.sub("/description", "String")
        # The timeline as the test sees it: "P" a frame with a person, "-" one without, "D" a
        # description. The person crosses the view, walks out behind the wall (~5 s out of
        # sight) and comes back: wait for a description after such an absence.
        timeline: list[str] = []

        def described_after_an_absence() -> bool:
            for d in dets.take():
                timeline.append("P" if "person" in list(d.labels) else "-")
            for msg in descriptions.take():
                assert "A person has been detected" in msg.data, msg.data  # the VLM's fixed prompt, answered
                timeline.append("D")
            line = "".join(timeline)
            return "D" in line and re.search(r"-{5}[-P]*P[-P]*D", line[line.index("D"):]) is not None

        wait_until(described_after_an_absence, 90, interval=0.2, what="a description after the person came back")
        line = "".join(timeline)
        # After the first description, each one follows a new appearance (no person -> person,
        # on_change), never a frame of a person who stayed in view: the describer does not run
        # per frame (the first may come from frames before the test subscribed).
        gaps = line[line.index("D"):].split("D")[1:-1]  # what came between two descriptions
        assert gaps and all("-P" in gap for gap in gaps), line
        assert line.count("P") > 2 * line.count("D"), line
        assert "[narrator] description #1" in system.output()
    finally:
        probe.close()
        assert system.stop() == 0


def test_composed_events_smart_stop_acts_in_the_drive_manager(tmp_path):
    system = _run(tmp_path, "composed_events.py", {})
    probe = Probe(system)
    try:
        system.wait_up(components=["sim", "drive_manager", "peripherals", "operator"], timeout=90)
        out = system.output
        odom, radar = probe.sub("/odom", "Odometry"), probe.sub("/radar_front", "Float32")
        wait_until(lambda: "EVENT auto-track person" in out(), 90, interval=0.2, what="the robot docked and handed over")
        # The creep into the dock went on close to the wall (radar < 0.3 m) after the stop.
        closest = min((m.data for m in radar.take()), default=None)
        assert closest is not None and closest < 0.2, closest
        assert all(abs(m.twist.twist.linear.x) < 0.1 for m in odom.take()[-5:])  # docked, standing
        time.sleep(1.0)  # a second smart stop, if any, would have come on the way in
        text = out()
        # The smart stop fired once, on the fast approach, and ran in the DriveManager's process.
        assert text.count("[drive_manager] stop: robot held still") == 1, text[-4000:]
        stop_at = text.index("[drive_manager] stop: robot held still")
        m = re.search(r"\[operator\] the robot was stopped on the way \(last seen at radar ([\d.]+) m, ([\d.]+) m/s\)", text)
        assert m and float(m.group(2)) > 0.1, text[-4000:]  # it was going fast when it was stopped
        assert _line(text, r"\[operator\] docked", stop_at) > 0
        # The other gates, each once: OR (lidar or bumper), AND (person, battery ok once
        # charging), AND NOT (person, not in manual override once handed over).
        for event in ("collision (lidar or bumper)", "describe person (battery ok)", "auto-track person (not in manual mode)"):
            assert text.count(f"EVENT {event}") == 1, (event, text[-4000:])
        assert _line(text, r"EVENT describe person", stop_at) > 0  # battery was low until docked
    finally:
        probe.close()
        assert system.stop() == 0
