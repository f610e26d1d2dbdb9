"""Shared pieces of the Create 2 tests: an emulator on a pty, a harness in lockstep with it."""
from __future__ import annotations

import os
import time

import pytest

from emos.actors.hardware.create2 import protocol as P
from emos.actors.hardware.create2.emulator import Create2Emulator
from emos.msgs.geometry import Twist


@pytest.fixture
def emulator(tmp_path):
    """A running emulator on open floor, reachable through a stable symlink (survives replugs).
    Its ticks come twice as fast as the real robot's: every test here reads emulator time."""
    emu = Create2Emulator(link=os.path.join(tmp_path, "ttyCreate2"), time_scale=2.0).start()
    yield emu
    emu.close()


def twist(v: float, w: float = 0.0) -> Twist:
    msg = Twist()
    msg.linear.x, msg.angular.z = v, w
    return msg


class Lockstep:
    """Moves a ComponentHarness's clock by the emulator's ticks: robot time = emulator time. The
    emulator is held between ticks and granted the next one only once the harness has caught up,
    so the driver sees every tick on time however busy the machine is."""

    def __init__(self, harness, emu):
        self.h, self.emu, self.last = harness, emu, emu.ticks
        emu.tick_limit = emu.ticks

    def run(self, seconds: float, *, until=None, timeout: float = 60.0):
        """Follow the emulator for ``seconds`` of its time (or until ``until()``); ``timeout`` wall s only bounds a hang."""
        end = self.emu.ticks + round(seconds / P.STREAM_PERIOD_S)
        deadline = time.monotonic() + timeout
        while self.emu.ticks < end:
            if until is not None and until():
                return True
            if time.monotonic() > deadline:
                raise TimeoutError(f"emulator stalled at tick {self.emu.ticks} (wanted {end})")
            ticks = self.emu.ticks
            if ticks > self.last:
                self.h.advance((ticks - self.last) * P.STREAM_PERIOD_S)
                self.last = ticks
            elif self.emu.tick_limit is not None and self.emu.tick_limit <= ticks:
                self.h.run_pending()
                self.emu.tick_limit = ticks + 1
            else:
                time.sleep(0.002)
                self.h.run_pending()
        return until() if until is not None else True
