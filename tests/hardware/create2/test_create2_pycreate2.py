"""Cross-check: the independent public driver ``pycreate2`` (PyPI) drives our emulator and reads its
sensors; where pycreate2 and our protocol module read the same bytes differently, the OI spec
decides and the test names the clause."""
from __future__ import annotations

import math
import time

import pytest

from emos.actors.hardware.create2 import protocol as P

pycreate2 = pytest.importorskip("pycreate2", reason="the cross-check needs pycreate2 (pip install 'emos[test]')")

pytestmark = pytest.mark.process


class _Create2(pycreate2.Create2):
    """pycreate2's Create2, whose shutdown (stop, LEDs off, display, Stop 173, close) runs when
    the test says, not from a finalizer at some later garbage collection."""

    def __del__(self) -> None:
        pass

    def shut_down(self) -> None:
        self.sleep_timer = 0.0  # its sleeps are for a real robot's sake
        pycreate2.Create2.__del__(self)


def _wait_ticks(emu, n: int, until=lambda: False) -> None:
    end = emu.ticks + n
    deadline = time.monotonic() + 30.0  # bounds a hang only
    while emu.ticks < end and time.monotonic() < deadline and not until():
        time.sleep(0.005)


def test_pycreate2_drives_the_emulator_and_reads_its_sensors(emulator, capsys):
    bot = _Create2(emulator.port)
    bot.sleep_timer = 0.02  # its mode changes sleep 0.5 s each for a real robot's sake; the emulator needs none
    try:
        bot.start()
        bot.safe()
        _wait_ticks(emulator, 2)
        assert emulator.mode == P.MODE_SAFE
        bot.drive_direct(200, 100)  # OI spec, Drive Direct: right first
        _wait_ticks(emulator, 4)
        assert (emulator.cmd_right, emulator.cmd_left) == (200, 100)
        assert emulator.drive_log[-1][2:] == (200, 100)
        _wait_ticks(emulator, 60)
        sensors = bot.get_sensors()  # [142][100]: the 80-byte group of packets 7..58
        assert sensors.open_interface_mode == P.MODE_SAFE
        assert sensors.velocity_right == 200 and sensors.velocity_left == 100
        assert sensors.battery_capacity == emulator.capacity_mah and 0 < sensors.battery_charge <= emulator.capacity_mah
        assert sensors.current < 0  # discharging while it drives
        right_counts = emulator.counts_right
        # The encoders count wheel travel: 508.8 counts per 72 mm wheel revolution (OI spec, packets 43/44).
        assert sensors.encoder_counts_right == pytest.approx(right_counts, abs=0.2 * right_counts)
        assert not sensors.bumps_wheeldrops.bump_left and not sensors.bumps_wheeldrops.wheeldrop_right

        emulator.set_wheel_drop(True)  # Safe mode: stop and revert to Passive (OI spec, Safe)
        _wait_ticks(emulator, 3)
        sensors = bot.get_sensors()
        assert sensors.bumps_wheeldrops.wheeldrop_left and sensors.bumps_wheeldrops.wheeldrop_right
        assert sensors.open_interface_mode == P.MODE_PASSIVE and sensors.velocity_right == 0
    finally:
        bot.shut_down()
    _wait_ticks(emulator, 100, until=lambda: emulator.mode == P.MODE_OFF)
    assert emulator.mode == P.MODE_OFF  # its Stop (173) arrived after the LED and display commands
    capsys.readouterr()


def test_encoder_sign_disagreement_the_spec_decides(emulator, capsys):
    """Backwards travel makes the counters negative. pycreate2 decodes packets 43/44 as unsigned
    (``>H``); the OI spec's Sensor Packets clause for packets 43/44 says "signed 16-bit, high byte
    first; rolls over to -32768 after it reaches 32767". Our decoder follows the spec; both agree
    modulo 2**16, which is all an odometry can use (``protocol.encoder_delta``)."""
    bot = _Create2(emulator.port)
    bot.sleep_timer = 0.02
    try:
        bot.start()
        bot.full()
        bot.drive_direct(-300, -300)
        _wait_ticks(emulator, 40)
        bot.drive_direct(0, 0)
        _wait_ticks(emulator, 20)
        bot.SCI.write(P.SENSORS, (P.PKT_GROUP_ALL,))
        raw = bot.SCI.read(80)
        theirs = pycreate2.packets.SensorPacketDecoder(raw)
        ours = P.decode_group_100(raw)
        assert ours[P.PKT_ENCODER_LEFT] < 0  # signed, per the spec
        assert ours[P.PKT_ENCODER_LEFT] == math.floor(emulator.counts_left)
        assert theirs.encoder_counts_left > 32767  # pycreate2's unsigned view of the same bytes
        assert theirs.encoder_counts_left == ours[P.PKT_ENCODER_LEFT] & 0xFFFF
        assert P.encoder_delta(theirs.encoder_counts_left, 0) == P.encoder_delta(ours[P.PKT_ENCODER_LEFT], 0)
        # everything else in the group decodes the same
        assert theirs.voltage == ours[P.PKT_VOLTAGE] and theirs.current == ours[P.PKT_CURRENT]
        assert theirs.open_interface_mode == ours[P.PKT_OI_MODE] == P.MODE_FULL
    finally:
        bot.shut_down()
    _wait_ticks(emulator, 100, until=lambda: emulator.mode == P.MODE_OFF)
    assert emulator.mode == P.MODE_OFF  # its Stop (173) arrived after the LED and display commands
    capsys.readouterr()
