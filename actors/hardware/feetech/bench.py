"""The servo-bus benchmark: full 6-joint SYNC_READ + SYNC_WRITE cycles per second at 1 Mbaud, emulated.

    from emos.actors.hardware.feetech.bench import servo_cycle_hz
    servo_cycle_hz(seconds=2.0)   # {"servo_cycle_hz": ..., "cycles": ..., ...}

Each cycle is one :meth:`.arm.ServoArm.cycle`, exactly what the ``FeetechArm`` component runs per
step: a SYNC_READ of position/speed/load (6 bytes) from every servo and a SYNC_WRITE of the goal
positions. The emulator charges the bus's wire time (10 bits per byte at the baud rate) and each
servo's Return Delay Time, which ``ServoArm`` sets to 0 at start as LeRobot does
(``factory_return_delay=True`` keeps the STS3215's factory 250 x 2 us instead). For
``emos bench hardware`` (the ``servo_cycle_hz`` field).
"""
from __future__ import annotations

import time

from .arm import SO100_JOINTS, ServoArm
from .emulator import BusEmulator


def servo_cycle_hz(seconds: float = 2.0, *, baudrate: int = 1_000_000, factory_return_delay: bool = False,
                   timeout: float = 0.02) -> dict:
    """Cycles per second over ``seconds``; ``timeout``: the driver's answer timeout (a servo whose
    answer comes later counts as an incomplete cycle)."""
    if not seconds > 0:
        raise ValueError(f"servo_cycle_hz: seconds must be > 0, got {seconds!r}")
    with BusEmulator(SO100_JOINTS.values(), baudrate=baudrate) as emu:
        arm = ServoArm(emu.path, SO100_JOINTS, baudrate=baudrate, timeout=timeout,
                       return_delay_time=None if factory_return_delay else 0)
        arm.start()
        try:
            cycles = incomplete = 0
            start = time.perf_counter()
            while (elapsed := time.perf_counter() - start) < seconds:
                reading = arm.cycle()
                cycles += 1
                if reading is None or len(reading.names) != len(SO100_JOINTS):
                    incomplete += 1
            return {"servo_cycle_hz": cycles / elapsed, "cycles": cycles, "incomplete_cycles": incomplete,
                    "dropped_bytes": arm.bus.dropped_bytes, "joints": len(SO100_JOINTS), "baudrate": baudrate,
                    "return_delay_us": 500 if factory_return_delay else 0}
        finally:
            arm.stop()


if __name__ == "__main__":
    import json

    print(json.dumps(servo_cycle_hz()))
    print(json.dumps(servo_cycle_hz(factory_return_delay=True)))
