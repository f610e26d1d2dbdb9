"""The RPLIDAR driver and component against the pty emulator: scans, faults, reconnection."""
from __future__ import annotations

import math
import time

import numpy as np
import pytest
import serial

from emos.actors.hardware.rplidar import protocol as P
from emos.actors.hardware.rplidar.driver import RplidarDriver, RplidarError, RplidarHealthError
from emos.actors.hardware.rplidar.emulator import MapRaycaster

from .conftest import HOUSE, SMOOTH_TOL, smooth_expected

pytestmark = pytest.mark.process  # real ptys and reader threads, paced in real time


def _wait(cond, timeout=20.0, what="condition"):
    deadline = time.monotonic() + timeout  # only bounds a hang
    while not cond():
        if time.monotonic() > deadline:
            raise TimeoutError(f"no {what} within {timeout} s")
        time.sleep(0.01)


def _scans(driver, n, timeout=20.0):
    out = []
    for _ in range(n):
        s = driver.wait_scan(timeout)
        assert s is not None, f"no scan from {driver.port} within {timeout} s"
        out.append(s)
    return out


def _bearings(scan):
    return scan.angle_min + scan.angle_increment * np.arange(len(scan.ranges))


def test_scans_at_10hz_match_the_ray_cast_of_the_map_with_nothing_corrupt(emulator):
    pose = (0.5, 0.3, 0.7)
    source = MapRaycaster(HOUSE)
    emu = emulator(source, pose)
    driver = RplidarDriver(emu.path)
    info = driver.start()
    try:
        assert info.model == 0x18 and info.firmware == "1.29" and driver.health == P.Health(0, 0)
        sent_before = emu.revolutions_sent
        scans = _scans(driver, 16)
        sent = emu.revolutions_sent - sent_before
    finally:
        driver.stop()
    # One scan per revolution the emulator sent (counted, not timed: a busy machine slows both
    # ends alike); the revolution in progress at either end may fall outside the window.
    assert len(scans) >= sent - 2, (len(scans), sent)
    assert all(s.nodes == 360 for s in scans)
    assert driver.corrupt_scans == 0 and driver.bytes_dropped == 0
    scan = scans[-1]
    expected = source(pose, _bearings(scan))
    both = np.isfinite(scan.ranges) & np.isfinite(expected)
    assert both.sum() > 200
    err = np.abs(scan.ranges[both] - expected[both])
    # beams are 1 deg wide and the emulator's angles start at a random fraction of a degree:
    # at an edge a beam may see the next wall; elsewhere the range is the cast to the quarter cell
    assert np.median(err) < 0.02 and np.mean(err < 0.05) > 0.9, (np.median(err), np.mean(err < 0.05))


def test_counter_clockwise_bearings_and_exact_ranges_on_a_smooth_world(emulator):
    emu = emulator()
    driver = RplidarDriver(emu.path)
    driver.start()
    try:
        scans = _scans(driver, 3)
    finally:
        driver.stop()
    for scan in scans:
        ok = np.isfinite(scan.ranges)
        assert ok.sum() >= 355
        err = np.abs(scan.ranges[ok] - smooth_expected(_bearings(scan)[ok]))
        assert err.max() < SMOOTH_TOL, err.max()


def test_garbage_on_the_line_drops_whole_scans_and_never_delivers_a_corrupt_one(emulator):
    emu = emulator()
    driver = RplidarDriver(emu.path)
    driver.start()
    try:
        _scans(driver, 2)
        rng = np.random.default_rng(5)
        injected = 0
        for i in range(12):
            junk = rng.integers(0, 256, 7 + i).astype(np.uint8).tobytes()
            emu.inject(junk)
            injected += len(junk)
            time.sleep(0.03)
        scans = _scans(driver, 8)
    finally:
        driver.stop()
    assert driver.corrupt_scans >= 1 and driver.bytes_dropped >= injected and driver.resyncs >= 1
    for scan in scans:  # every delivered scan is exact
        ok = np.isfinite(scan.ranges)
        assert np.abs(scan.ranges[ok] - smooth_expected(_bearings(scan)[ok])).max() < SMOOTH_TOL


def test_motor_must_spin_up_before_nodes_flow(emulator):
    """A2: SCAN gets its descriptor at once, but nodes come only after SET_MOTOR_PWM and the
    spin-up (document §4 SCAN: 'only after the motor rotation becomes stable')."""
    emu = emulator(model="A2", spin_up_s=0.3)
    with serial.Serial(emu.path, 115200, timeout=0.3) as port:
        port.write(P.request(P.CMD_SCAN))
        assert port.read(7) == P.SCAN_DESCRIPTOR.encode()
        assert port.read(50) == b""  # motor off: no node (the read only waits out its timeout)
        port.write(P.motor_pwm_request(660))
        port.write(P.request(P.CMD_SCAN))
        assert port.read(7) == P.SCAN_DESCRIPTOR.encode()
        port.timeout = 5.0
        first = port.read(50)
    assert P.NodeParser().feed(first).start.any() or len(first) == 50
    assert emu.requests[1] == (P.CMD_SET_MOTOR_PWM, b"\x94\x02")


def test_unplugged_device_reports_the_port_and_the_stream_resumes_on_replug(emulator):
    emu = emulator()
    driver = RplidarDriver(emu.path, stall_timeout=1.0)
    driver.start()
    try:
        _scans(driver, 2)
        emu.unplug()
        _wait(lambda: driver.error is not None, what="error after unplug")
        assert emu.path in driver.error and "lost" in driver.error
        time.sleep(0.3)  # a few reconnect attempts fail while it is away
        assert driver.error is not None and emu.path in driver.error
        emu.replug()
        _wait(lambda: driver.reconnects >= 1, what="reconnect")
        driver.get_scans()
        scans = _scans(driver, 3)
        assert driver.error is None and driver.disconnects == 1
    finally:
        driver.stop()
    ok = np.isfinite(scans[-1].ranges)
    assert np.abs(scans[-1].ranges[ok] - smooth_expected(_bearings(scans[-1])[ok])).max() < SMOOTH_TOL


def test_missing_and_taken_ports_fail_at_start_naming_the_port(emulator, tmp_path):
    missing = str(tmp_path / "ttyUSB9")
    with pytest.raises(RplidarError, match=f"{missing} does not exist"):
        RplidarDriver(missing).start()
    emu = emulator()
    with serial.Serial(emu.path, 115200, exclusive=True), pytest.raises(RplidarError, match=f"{emu.path} is taken by another process"):
        RplidarDriver(emu.path).start()


def test_protection_stop_is_reset_once_then_a_hardware_failure_naming_the_port(emulator):
    emu = emulator(health=P.Health(P.HEALTH_ERROR, 0x0102))
    with pytest.raises(RplidarHealthError, match=rf"{emu.path}.*Protection Stop.*0x0102"):
        RplidarDriver(emu.path).start()
    cmds = [c for c, _ in emu.requests]
    assert cmds[:4] == [P.CMD_STOP, P.CMD_GET_HEALTH, P.CMD_RESET, P.CMD_GET_HEALTH]  # Fig. 5-1
    assert P.CMD_SCAN not in cmds


def test_component_publishes_laserscan_and_reports_system_failure_naming_the_port(emulator):
    from emos.actors.hardware.rplidar.component import Rplidar, RplidarConfig
    from emos.testing import ComponentHarness

    emu = emulator()
    comp = Rplidar(component_name="lidar", config=RplidarConfig(port=emu.path, stall_timeout=1.0))
    with ComponentHarness(comp) as h:
        got = []
        deadline = time.monotonic() + 20
        while len(got) < 2 and time.monotonic() < deadline:
            h.advance(h.tick)
            got += h.outputs("/scan")
            time.sleep(0.01)
        assert len(got) >= 2 and h.health.is_healthy
        msg = got[-1]
        assert msg.angle_min == pytest.approx(-math.pi) and msg.angle_increment == pytest.approx(2 * math.pi / 360)
        ok = np.isfinite(msg.ranges)
        assert np.abs(msg.ranges[ok] - smooth_expected(msg.angles()[ok])).max() < SMOOTH_TOL
        emu.unplug()
        deadline = time.monotonic() + 20
        while not h.health.is_system_fail and time.monotonic() < deadline:
            h.advance(h.tick)
            time.sleep(0.01)
        assert h.health.is_system_fail
        assert emu.path in h.component.health_status.to_msg().message or emu.path in (comp.driver.error or "")


def test_component_activation_fails_on_a_missing_port_with_its_name(tmp_path):
    from emos.actors.hardware.rplidar.component import Rplidar, RplidarConfig
    from emos.testing import ComponentHarness

    missing = str(tmp_path / "ttyACM7")
    comp = Rplidar(component_name="lidar", config=RplidarConfig(port=missing))
    with ComponentHarness(comp, activate=False) as h:
        with pytest.raises(Exception, match=missing):
            h.activate()
        assert comp.health_status.is_system_fail and missing in comp.health_status.to_msg().message


def test_emulator_command_line_prints_its_port_and_serves_the_map(tmp_path):
    import subprocess
    import sys

    proc = subprocess.Popen([sys.executable, "-m", "emos.actors.hardware.rplidar.emulator", "--map", HOUSE,
                             "--pose", "0.5,0.3,0.7"], stdout=subprocess.PIPE, text=True)
    try:
        port = proc.stdout.readline().strip()
        assert port.startswith("/dev/pts/"), port
        driver = RplidarDriver(port)
        driver.start()
        try:
            (scan,) = _scans(driver, 1)
        finally:
            driver.stop()
        expected = MapRaycaster(HOUSE)((0.5, 0.3, 0.7), _bearings(scan))
        both = np.isfinite(scan.ranges) & np.isfinite(expected)
        assert both.sum() > 200 and np.median(np.abs(scan.ranges[both] - expected[both])) < 0.02
    finally:
        proc.terminate()
        assert proc.wait(10) == 0


def test_emulator_rejects_a_bad_pose():
    import subprocess
    import sys

    r = subprocess.run([sys.executable, "-m", "emos.actors.hardware.rplidar.emulator", "--map", HOUSE, "--pose", "1,2"],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "--pose must be x,y,theta" in r.stderr
