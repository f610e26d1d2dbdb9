"""The emulator and our encoder cross-checked by Feetech's own SDK (PyPI ``feetech-servo-sdk``,
module ``scservo_sdk``), an independent implementation of the same protocol.

Where the SDK and we could disagree the protocol document decides; so far they agree on every
clause exercised here: framing and checksum ("Instruction packet", "Status packet"), PING then
READ of the model number at address 3 (SDK ``ping``), SYNC_READ's answer order and length
("Sync Read": one status packet per listed servo, in order), SYNC_WRITE's parameter layout
("Sync Write"), and sign-magnitude speeds (STS memory table: "BIT15 is the direction bit").
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys

import pytest

from emos.actors.hardware.feetech import protocol as P
from emos.actors.hardware.feetech.driver import FeetechBus
from emos.actors.hardware.feetech.protocol import Reg

sdk = pytest.importorskip("scservo_sdk", reason="the test extra installs feetech-servo-sdk")

pytestmark = pytest.mark.process  # an emulator on a real pty; one test starts it as a process


@pytest.fixture
def sdk_port(emulator, monkeypatch):
    # The SDK waits 2 x LATENCY_TIMER (the USB adapter's 16 ms) + 2 ms for an answer. On a loaded
    # test machine the emulator's thread can be starved longer than that: give it a slow adapter.
    monkeypatch.setattr(sdk.port_handler, "LATENCY_TIMER", 250)
    port = sdk.PortHandler(emulator.path)
    assert port.openPort(), f"the SDK could not open {emulator.path}"
    yield port
    port.closePort()


def test_sdk_ping_read_write(emulator, sdk_port):
    ph = sdk.PacketHandler(0)  # protocol_end 0: STS little-endian words
    for servo_id in range(1, 7):
        model, result, error = ph.ping(sdk_port, servo_id)
        assert (model, result, error) == (P.STS3215_MODEL, sdk.COMM_SUCCESS, 0), ph.getTxRxResult(result)
    assert ph.ping(sdk_port, 9)[1] == sdk.COMM_RX_TIMEOUT  # nobody there: the SDK times out, as on a real bus
    assert ph.read2ByteTxRx(sdk_port, 3, Reg.PRESENT_POSITION.address) == (2048, sdk.COMM_SUCCESS, 0)
    assert ph.write1ByteTxRx(sdk_port, 3, Reg.TORQUE_ENABLE.address, 1) == (sdk.COMM_SUCCESS, 0)
    # a negative speed written the SDK's way (SCS_TOSCS, bit 15) reads back as ours decodes it
    assert ph.write2ByteTxRx(sdk_port, 3, Reg.GOAL_SPEED.address, sdk.SCS_TOSCS(-700, 15)) == (sdk.COMM_SUCCESS, 0)
    assert emulator.servos[3].get(Reg.GOAL_SPEED) == -700
    raw, result, _ = ph.read2ByteTxRx(sdk_port, 3, Reg.GOAL_SPEED.address)
    assert result == sdk.COMM_SUCCESS and sdk.SCS_TOHOST(raw, 15) == -700


def test_sdk_group_sync_write_and_read(emulator, sdk_port):
    ph = sdk.PacketHandler(0)
    writer = sdk.GroupSyncWrite(sdk_port, ph, Reg.GOAL_POSITION.address, 2)
    for servo_id in range(1, 7):
        assert writer.addParam(servo_id, [sdk.SCS_LOBYTE(1000 + servo_id), sdk.SCS_HIBYTE(1000 + servo_id)])
    assert writer.txPacket() == sdk.COMM_SUCCESS
    reader = sdk.GroupSyncRead(sdk_port, ph, Reg.GOAL_POSITION.address, 2)
    for servo_id in range(1, 7):
        reader.addParam(servo_id)
    assert reader.txRxPacket() == sdk.COMM_SUCCESS
    assert {i: reader.getData(i, Reg.GOAL_POSITION.address, 2) for i in range(1, 7)} == {i: 1000 + i for i in range(1, 7)}
    assert emulator.bad_packets == 0  # every byte the SDK sent was a well-formed packet to the emulator
    # and our driver reads what the SDK wrote
    sdk_port.closePort()
    with FeetechBus(emulator.path, timeout=0.5) as bus:
        assert bus.sync_read(Reg.GOAL_POSITION, range(1, 7)) == {i: 1000 + i for i in range(1, 7)}
    sdk_port.openPort()


class RecordingPort:
    """Stands where the SDK's port handler stands, to see the bytes its packet builder makes."""

    def __init__(self):
        self.is_using, self.sent = False, []

    def clearPort(self):
        pass

    def writePort(self, packet):
        self.sent.append(bytes(packet))
        return len(packet)

    def setPacketTimeout(self, *_):
        pass


def test_our_encoder_makes_the_sdks_bytes():
    ph, port = sdk.PacketHandler(0), RecordingPort()
    for build in (lambda: ph.readTx(port, 5, 56, 6), lambda: ph.syncReadTx(port, 56, 2, [1, 2, 3, 4, 5, 6], 6),
                  lambda: ph.writeTxOnly(port, 2, 42, 2, [0x00, 0x08]),
                  lambda: ph.syncWriteTxOnly(port, 42, 2, [1, 0x10, 0x04, 6, 0xFF, 0x0F], 6)):
        assert build() == sdk.COMM_SUCCESS
        port.is_using = False  # the SDK leaves it set while it would wait for an answer
    assert port.sent == [P.read(5, 56, 6), P.sync_read(56, 2, range(1, 7)), P.write(2, 42, b"\x00\x08"),
                         P.sync_write(42, 2, {1: b"\x10\x04", 6: b"\xff\x0f"})]


def test_emulator_cli_prints_its_pty_and_serves_the_sdk(monkeypatch):
    monkeypatch.setattr(sdk.port_handler, "LATENCY_TIMER", 250)  # a loaded machine: see sdk_port
    proc = subprocess.Popen([sys.executable, "-m", "emos.actors.hardware.feetech.emulator", "--ids", "1,2,3"],
                            stdout=subprocess.PIPE, text=True)
    try:
        path = proc.stdout.readline().strip()
        assert os.path.exists(path), f"emulator printed {path!r}"
        port = sdk.PortHandler(path)
        assert port.openPort()
        try:
            ph = sdk.PacketHandler(0)
            assert [ph.ping(port, i)[:2] for i in (1, 2, 3)] == [(P.STS3215_MODEL, sdk.COMM_SUCCESS)] * 3
        finally:
            port.closePort()
    finally:
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=30) == 0
        proc.stdout.close()
    assert not os.path.exists(path)
