"""Shared pieces of the Feetech tests: an emulated 6-servo bus on a pty."""
from __future__ import annotations

import pytest

from emos.actors.hardware.feetech.emulator import BusEmulator


@pytest.fixture
def emulator(tmp_path):
    """Servos 1..6 behind a stable symlink in tmp_path (it survives unplug/replug)."""
    emu = BusEmulator((1, 2, 3, 4, 5, 6), link_dir=str(tmp_path)).start()
    yield emu
    emu.close()
