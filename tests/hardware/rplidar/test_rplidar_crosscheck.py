"""Cross-check with an independent public driver, pyrplidar (PyPI), talking to our emulator and
decoding our bytes. Where pyrplidar and we disagree, Slamtec's protocol document decides and the
test names the clause."""
from __future__ import annotations

import numpy as np
import pytest

from emos.actors.hardware.rplidar import protocol as P

from .conftest import smooth_world

pyrplidar = pytest.importorskip("pyrplidar", reason="pyrplidar is in the test extra: pip install -e '.[test]'")
pyrplidar_protocol = pytest.importorskip("pyrplidar_protocol")

pytestmark = pytest.mark.process  # a pty emulator paced in real time


def test_pyrplidar_reads_the_emulator_info_health_and_scan(emulator):
    emu = emulator(health=P.Health(P.HEALTH_WARNING, 0x1234))
    lidar = pyrplidar.PyRPlidar()
    lidar.connect(port=emu.path, baudrate=115200, timeout=3)
    try:
        info = lidar.get_info()
        assert (info.model, info.firmware_major, info.firmware_minor, info.hardware) == (0x18, 1, 29, 7)
        assert info.serialnumber == emu.info.serial_hex
        health = lidar.get_health()
        assert health.status == P.HEALTH_WARNING
        # Disagreement: pyrplidar reads error_code as (byte1 << 8) + byte2 (big-endian) and gets
        # 0x3412. The document decides: GET_HEALTH, Fig. 4-19 "Format of a Device Health Data
        # Response Packet" puts error_code[7:0] at offset +1 and error_code[15:8] at +2, and §2
        # says "Little endian byte order is used". Ours reads 0x1234, as the emulator sent.
        assert health.error_code == 0x3412
        assert P.Health.decode(emu.health.encode()).error_code == 0x1234
        scan = lidar.start_scan()
        measures = [m for _, m in zip(range(1200), scan())]
        lidar.stop()
    finally:
        lidar.disconnect()
    # Fig. 4-5: S marks the first node of each revolution; 360 nodes per revolution
    starts = [i for i, m in enumerate(measures) if m.start_flag]
    assert len(starts) >= 3 and all(b - a == 360 for a, b in zip(starts, starts[1:]))
    # pyrplidar's angle is the raw clockwise heading (Fig. 4-6); the world was cast counter-
    # clockwise at -angle: an independent decoder finds the same ranges in our bytes
    ang = np.radians([m.angle for m in measures])
    dist = np.array([m.distance for m in measures]) / 1000.0
    assert np.abs(dist - smooth_world(None, -ang)).max() < 0.001


def test_request_bytes_are_identical_to_pyrplidars():
    cmds = {P.CMD_STOP: pyrplidar_protocol.RPLIDAR_CMD_STOP, P.CMD_RESET: pyrplidar_protocol.RPLIDAR_CMD_RESET,
            P.CMD_SCAN: pyrplidar_protocol.RPLIDAR_CMD_SCAN, P.CMD_GET_INFO: pyrplidar_protocol.RPLIDAR_CMD_GET_INFO,
            P.CMD_GET_HEALTH: pyrplidar_protocol.RPLIDAR_CMD_GET_HEALTH}
    for ours, theirs in cmds.items():
        assert P.request(ours) == pyrplidar_protocol.PyRPlidarCommand(theirs).raw_bytes
    for pwm in (0, 1, 660, 1023):  # §2 checksum over A5, cmd, size and payload
        theirs = pyrplidar_protocol.PyRPlidarCommand(pyrplidar_protocol.RPLIDAR_CMD_SET_MOTOR_PWM, pwm.to_bytes(2, "little"))
        assert P.motor_pwm_request(pwm) == theirs.raw_bytes


def test_node_decoding_agrees_with_pyrplidar_on_valid_nodes_and_differs_only_where_the_check_bits_fail():
    rng = np.random.default_rng(9)
    n = 2000
    raw = P.encode_nodes(np.arange(n) % 360 == 0, rng.integers(0, 64, n), rng.integers(0, P.ANGLE_Q6_FULL, n),
                         rng.integers(0, 0x10000, n))
    ours = P.decode_nodes(raw)
    theirs = [pyrplidar_protocol.PyRPlidarMeasurement(raw[i:i + 5]) for i in range(0, len(raw), 5)]
    assert [m.start_flag for m in theirs] == ours.start.tolist()
    assert [m.quality for m in theirs] == ours.quality.tolist()
    assert np.array_equal([m.angle for m in theirs], ours.angle_deg)
    assert np.array_equal([m.distance for m in theirs], ours.distance_mm)
    # Disagreement: out of sync by one byte, pyrplidar decodes every 5 bytes as a node (it does
    # not test S-bar or C); Fig. 4-5 says S-bar is "always !S" and C is "constantly set to 1",
    # both usable "as a data check bit": those nodes are not nodes, and ours rejects them.
    shifted = raw[1:1 + 5 * 100]
    decoded = [pyrplidar_protocol.PyRPlidarMeasurement(shifted[i:i + 5]) for i in range(0, len(shifted), 5)]
    truth = set(zip(ours.angle_q6.tolist(), ours.distance_q2.tolist()))
    assert sum((round(m.angle * 64), round(m.distance * 4)) not in truth for m in decoded) > 90
    flat = np.frombuffer(shifted, np.uint8)
    assert not P.node_valid_mask(flat)[::5].all()
    got = P.NodeParser(max_step_deg=None).feed(shifted)  # check bits alone (these angles are random): re-locks on real nodes
    assert len(got) >= 95 and all(k in truth for k in zip(got.angle_q6.tolist(), got.distance_q2.tolist()))
