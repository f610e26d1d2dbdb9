"""The Create2Base component against the emulated Create 2 on a pty: odometry, watchdog, bump stop,
unplug/replug, bad ports. Times are the emulator's (15 ms ticks), never wall-clock budgets."""
from __future__ import annotations

import math
import os

import pytest
import serial

from emos.actors.hardware.create2 import protocol as P
from emos.actors.hardware.create2.component import Create2Base
from emos.actors.hardware.create2.driver import Create2Link, Create2PortError
from emos.testing import ComponentHarness

from .conftest import Lockstep, twist

pytestmark = pytest.mark.process  # an emulator thread on a real pty; the CLI test starts a process


def _drive(step: Lockstep, v: float, w: float, seconds: float, every: float = 0.1) -> float:
    """Publish /cmd_vel every ``every`` s of robot time for ``seconds``, as a controller does;
    returns the robot time of the last one (steps are whole emulator ticks: not exactly ``every``)."""
    n = max(1, round(seconds / every))
    fed = step.h.time
    for _ in range(n):
        fed = step.h.time
        step.h.feed("/cmd_vel", twist(v, w))
        step.run(every)
    return fed


def test_square_odometry_matches_emulator_truth(emulator):
    with ComponentHarness(Create2Base(port=emulator.link)) as h:
        step = Lockstep(h, emulator)
        assert step.run(5.0, until=lambda: h.latest("/battery") is not None)
        battery_start = h.latest("/battery").percentage
        path = 0.0
        for _ in range(4):
            _drive(step, 0.3, 0.0, 1.2)
            _drive(step, 0.0, 2.0, math.pi / 4)  # ~90 degrees; the truth says how much exactly
            path += 0.3 * 1.2 + math.pi / 4
        _drive(step, 0.0, 0.0, 0.6)  # stand still, let the last frames arrive
        odo = h.latest("/odom")
        x, y, th = emulator.truth()
        moved = math.hypot(x, y)
        assert emulator.counts_left > 1500 and emulator.counts_right > 1500  # it really drove
        # Within encoder resolution: < 1 count per wheel in distance, plus the heading error of
        # up to 2 counts across the wheel base carried along the path.
        tol_xy = 2 * P.M_PER_COUNT + (2 * P.M_PER_COUNT / P.WHEEL_BASE_M) * path
        tol_th = 2 * P.M_PER_COUNT / P.WHEEL_BASE_M
        p = odo.pose.pose.position
        assert abs(p.x - x) <= tol_xy and abs(p.y - y) <= tol_xy, (p.x, p.y, x, y, tol_xy)
        q = odo.pose.pose.orientation
        assert abs(math.remainder(2 * math.atan2(q.z, q.w) - th, 2 * math.pi)) <= tol_th
        assert moved < 0.3  # a closed square (approximately): the loop came back near the start
        assert h.component.parser.dropped_bytes == 0
        assert 0 < h.latest("/battery").percentage < battery_start <= 1.0  # fraction of capacity, draining


def test_watchdog_sends_one_stop_after_cmd_timeout_of_robot_time(emulator):
    with ComponentHarness(Create2Base(port=emulator.link, cmd_timeout=0.5)) as h:
        step = Lockstep(h, emulator)
        last_cmd_time = _drive(step, 0.2, 0.0, 1.0)  # fresh commands every 0.1 s: no watchdog
        assert h.component.stops_sent == 0 and emulator.cmd_right == 200
        last_cmd_tick = emulator.drive_log[-1][0]
        step.run(1.5)  # silence
        zeros = [(t, r, left) for t, _, r, left in emulator.drive_log if t >= last_cmd_tick and (r, left) == (0, 0)]
        assert len(zeros) == 1 and h.component.stops_sent == 1  # once, not every period
        (stop_time, why), = h.component.stop_log
        assert "watchdog" in why
        waited = stop_time - last_cmd_time  # robot time (the harness's clock, in step with the emulator's ticks)
        # cmd_timeout, plus at most one poll period (15 ms) and one harness tick of quantization
        assert 0.5 <= waited <= 0.5 + 2 * P.STREAM_PERIOD_S + 1e-9, waited
        assert emulator.cmd_right == emulator.cmd_left == 0


def test_bump_stops_the_base_while_commands_keep_coming(emulator):
    emulator.add_obstacle(0.40, 0.0)  # a chair leg 40 cm ahead; the body's radius is 17 cm
    with ComponentHarness(Create2Base(port=emulator.link)) as h:
        step = Lockstep(h, emulator)
        for _ in range(40):  # the navigation stack keeps saying "forward"
            h.feed("/cmd_vel", twist(0.25))
            step.run(0.1)
            if emulator.bumps:
                break
        assert emulator.bumps, "never reached the obstacle"
        bump_tick = emulator.ticks
        _drive(step, 0.25, 0.0, 1.0)  # still commanding forward for a whole second
        forward = [(r, left) for t, _, r, left in emulator.drive_log if t > bump_tick + 2 and (r > 0 or left > 0)]
        assert forward == []  # not one of the forward commands reached the robot
        assert any("bumper" in why for _, why in h.component.stop_log)
        assert emulator.cmd_right == emulator.cmd_left == 0 and h.latest("/bumper").data is True
        _drive(step, -0.1, 0.0, 1.0)  # reverse is let through: the bump clears
        assert not emulator.bumps and emulator.cmd_right == -100
        assert h.latest("/bumper").data is False


def test_unplug_reports_system_failure_naming_port_and_replug_resumes(emulator):
    comp = Create2Base(port=emulator.link)
    with ComponentHarness(comp) as h:
        step = Lockstep(h, emulator)
        _drive(step, 0.1, 0.0, 0.3)
        emulator.unplug()  # the cable is pulled while the robot drives at 0.1 m/s
        assert step.run(5.0, until=lambda: comp.health_status.is_system_fail)
        assert emulator.link in comp.health_status().message
        assert emulator.cmd_right == 100  # unreachable: the robot keeps its last command, as a real one does
        frames_before = comp.parser.frames
        step.run(0.3)
        emulator.replug()
        assert step.run(10.0, until=lambda: comp.health_status.is_healthy and comp.parser.frames > frames_before + 5)
        # Reachable again: the first thing it gets is a stop, before any new command arrives.
        assert emulator.cmd_right == emulator.cmd_left == 0
        assert comp.stop_log[-1][1] == "reconnected"
        _drive(step, 0.2, 0.0, 0.3)  # commands reach the new port
        assert emulator.cmd_right == 200 and emulator.mode == P.MODE_SAFE


def test_an_unplugged_link_never_leads_to_the_pty_that_takes_its_old_number(tmp_path):
    """The kernel gives a closed pty's number to the next pty opened on the machine (another
    test's emulator, in another worker). A link left behind by the unplug would take a
    reconnecting driver to that device: it must go with the device and come back with it."""
    from emos.actors.hardware.create2.emulator import Create2Emulator

    link = str(tmp_path / "ttyCreate2")
    with Create2Emulator(link=link) as first:
        first.unplug()
        with Create2Emulator() as stranger:  # most likely takes old_port's number
            assert not os.path.lexists(link), f"{link} still leads to {os.readlink(link)} (the stranger is {stranger.port})"
            first.replug()
            assert os.path.realpath(link) == first.port != stranger.port
    assert not os.path.lexists(link)


def test_missing_port_is_a_clear_error_naming_it(tmp_path):
    port = str(tmp_path / "ttyUSB9")
    with pytest.raises(Create2PortError, match=r"ttyUSB9.*does not exist"):
        Create2Link(port).open()
    with pytest.raises(Exception, match="ttyUSB9"):
        ComponentHarness(Create2Base(port=port))


def test_taken_port_is_a_clear_error_naming_it(emulator):
    holder = serial.Serial(emulator.link, exclusive=True)
    try:
        with pytest.raises(Create2PortError, match=r"ttyCreate2.*taken by another process"):
            Create2Link(emulator.link).open()
    finally:
        holder.close()


def test_emulator_safe_mode_wheel_drop_and_cliff_revert_to_passive(emulator):
    link = Create2Link(emulator.link)
    link.open()
    try:
        link.drive_direct(100, 100)
        Lockstep(_NoHarness(), emulator).run(0.2)
        assert emulator.mode == P.MODE_SAFE and emulator.cmd_right == 100
        emulator.set_wheel_drop(True)  # OI spec, Safe mode: stop the motors, revert to Passive
        Lockstep(_NoHarness(), emulator).run(0.1)
        assert emulator.mode == P.MODE_PASSIVE and emulator.cmd_right == 0
        link.drive_direct(100, 100)  # Passive ignores actuator commands
        Lockstep(_NoHarness(), emulator).run(0.2)
        assert emulator.cmd_right == 0
        frames = link.take_frames()
        assert frames and frames[-1].wheel_dropped and frames[-1].get(P.PKT_OI_MODE) == P.MODE_PASSIVE
        emulator.set_wheel_drop(False)  # back on the floor; Safe again; a cliff does the same
        link._send(bytes([P.SAFE]))
        link.drive_direct(100, 100)
        Lockstep(_NoHarness(), emulator).run(0.2)
        assert emulator.mode == P.MODE_SAFE and emulator.cmd_right == 100
        emulator.set_cliff(1, True)  # front left
        Lockstep(_NoHarness(), emulator).run(0.1)
        assert emulator.mode == P.MODE_PASSIVE and emulator.cmd_right == 0
        assert link.take_frames()[-1].cliffs == (False, True, False, False)
    finally:
        link.close()


class _NoHarness:
    def advance(self, seconds):
        pass

    def run_pending(self):
        pass


def test_emulator_command_line_prints_its_pty(tmp_path):
    import subprocess
    import sys

    from emos.actors.sim.data import __file__ as data_init
    house = os.path.join(os.path.dirname(data_init), "house.yaml")
    proc = subprocess.Popen([sys.executable, "-m", "emos.actors.hardware.create2.emulator", "--map", house, "--pose", "1.0,1.0,0"],
                            stdout=subprocess.PIPE, text=True)
    try:
        port = proc.stdout.readline().strip()
        assert port.startswith("/dev/pts/")
        link = Create2Link(port)
        link.open()
        try:
            deadline_frames = 0
            while deadline_frames < 200 and link.parser.frames < 3:
                import time
                time.sleep(0.02)
                deadline_frames += 1
            assert link.parser.frames >= 3
        finally:
            link.close()
    finally:
        proc.terminate()
        proc.wait(timeout=10)


def test_emulator_bumps_into_a_wall_of_a_ros_map(tmp_path):
    """A map_server YAML + PGM (written by our saver, read by our loader) is the emulator's world:
    driving at a wall stops at the wall with both bumpers pressed (head-on)."""
    import numpy as np

    from emos.actors.hardware.create2.emulator import Create2Emulator
    from emos.actors.nav.maps.grid import OccupancyGridMap
    from emos.actors.nav.maps.map_yaml import load_map, save_map

    cells = np.zeros((60, 60), dtype=np.int8)  # 3 m x 3 m at 5 cm
    cells[:, 40] = 100  # a wall: the column of cells from x = 2.00 to 2.05 m
    path = save_map(OccupancyGridMap(data=cells, resolution=0.05, origin=(0.0, 0.0, 0.0)), tmp_path / "wall.yaml")
    emu = Create2Emulator(load_map(path), pose=(1.0, 1.5, 0.0), time_scale=2.0).start()
    link = Create2Link(emu.port)
    try:
        link.open()
        Lockstep(_NoHarness(), emu).run(0.1, until=lambda: emu.mode == P.MODE_SAFE)
        link.drive_direct(300, 300)
        assert Lockstep(_NoHarness(), emu).run(10.0, until=lambda: emu.bumps == P.BUMP_LEFT | P.BUMP_RIGHT)
        Lockstep(_NoHarness(), emu).run(0.5)  # keeps pushing: the wall holds
        x, y, _ = emu.truth()
        assert 2.025 - emu.radius - 0.02 <= x <= 2.025 - emu.radius and y == pytest.approx(1.5)
        frames = link.take_frames()
        assert frames[-1].bump_left and frames[-1].bump_right
    finally:
        link.close()
        emu.close()


def test_emulator_command_parser_handles_split_and_variable_length_commands():
    """Commands arrive in arbitrary pieces; Song (140) and Stream (148) carry their own lengths
    (OI spec, Commands Quick Reference); bytes before Start are ignored."""
    from emos.actors.hardware.create2.emulator import Create2Emulator

    emu = Create2Emulator()  # not started: no ticks, commands fed by hand
    try:
        emu.feed(bytes([P.SAFE]) + P.drive_direct(100, 100))  # before Start: the OI listens to nothing
        assert emu.mode == P.MODE_OFF and emu.cmd_right == 0
        song = bytes([P.SONG, 0, 2, 60, 16, 62, 16])  # song 0, two notes
        stream = P.stream_request([7, 43])
        data = bytes([P.START, P.FULL]) + song + P.drive_direct(-250, 250) + stream + P.pause_resume(False)
        for i in range(len(data)):
            emu.feed(data[i:i + 1])  # one byte at a time
        assert emu.mode == P.MODE_FULL and (emu.cmd_right, emu.cmd_left) == (-250, 250)
        assert emu.stream_ids == [7, 43] and emu.stream_paused
    finally:
        emu.close()
