"""``/cmd_vel`` published -> Drive Direct bytes on the wire, through a real component process.

For ``emos bench hardware`` (issue 37, Measure): an emulated Create 2 runs in this process; a
recipe with one ``Create2Base`` on the emulator's pty runs under ``emos run`` in a child
process; this process publishes Twists on ``/cmd_vel`` of that run and times each one until
the emulator reads the matching Drive Direct bytes from the pty. The time is taken where the
bytes arrive (the emulator's read), so it includes the topic hop, the component's step, the
serial write and the pty: an upper bound of "published -> written".
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from .emulator import Create2Emulator

_RECIPE = """\
from emos import Launcher
from emos.actors.hardware.create2.component import Create2Base

base = Create2Base(component_name="create2_bench", port={port!r}, cmd_timeout=5.0)
launcher = Launcher()
launcher.add_pkg(components=[base])
launcher.bringup()
"""


def bench_cmd_to_wire(commands: int = 300, rate: float = 50.0, timeout: float = 120.0) -> dict[str, Any]:
    """Publish ``commands`` Twists at ``rate`` Hz; return p50/p99/max latency in ms and the count."""
    from emos.msgs.geometry import Twist
    from emos.transport.context import RunContext, runtime_root
    from emos.transport.pubsub import Publisher

    emu = Create2Emulator().start()
    arrived = threading.Event()
    emu.on_drive = lambda right, left: arrived.set()
    workdir = tempfile.TemporaryDirectory(prefix="emos-bench-create2-")
    script = Path(workdir.name) / "recipe.py"
    script.write_text(_RECIPE.format(port=emu.port))
    proc = subprocess.Popen([sys.executable, "-m", "emos", "run", str(script)], cwd=workdir.name,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    pub = None
    try:
        end = time.monotonic() + timeout
        run_dir = None
        while run_dir is None or not (emu.stream_ids and emu.mode == 2):  # the component opened the port: Start, Safe, Stream
            if proc.poll() is not None or time.monotonic() > end:
                raise RuntimeError(f"the Create 2 bench recipe did not start (exit code {proc.poll()})")
            if run_dir is None:
                run_dir = next((d for d in runtime_root().iterdir() if d.name.startswith(f"{proc.pid}-")), None)
            time.sleep(0.05)
        pub = Publisher(RunContext(run_dir.name, run_dir, owner=False), "/cmd_vel", Twist, publisher_id="bench", depth=16)
        latencies: list[float] = []
        for i in range(-20, commands):  # 20 warm-up commands (the subscriber finds the new ring)
            mm_s = 100 + (i % 300)  # distinct from the previous one: each sample is matched by value
            msg = Twist()
            msg.linear.x = mm_s / 1000.0
            seen = len(emu.drive_log)
            arrived.clear()
            t0 = time.perf_counter()
            pub.publish(msg)
            deadline = time.monotonic() + (10.0 if i >= 0 else 1.0)
            hit = None
            while hit is None and time.monotonic() < deadline:
                arrived.wait(0.05)
                arrived.clear()
                hit = next((stamp for _, stamp, r, left in emu.drive_log[seen:] if r == left == mm_s), None)
            if hit is None and i >= 0:
                raise RuntimeError(f"Drive Direct {mm_s} mm/s never reached the emulator (command {i})")
            if hit is not None and i >= 0:
                latencies.append(hit - t0)
            time.sleep(max(0.0, 1.0 / rate - (time.perf_counter() - t0)))
        ms = np.asarray(latencies) * 1000.0
        return {"cmd_to_wire_p50_ms": round(float(np.percentile(ms, 50)), 3),
                "cmd_to_wire_p99_ms": round(float(np.percentile(ms, 99)), 3),
                "cmd_to_wire_max_ms": round(float(ms.max()), 3), "commands": len(latencies)}
    finally:
        if pub is not None:
            pub.close()
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
            try:
                proc.wait(30)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        emu.close()
        workdir.cleanup()


if __name__ == "__main__":
    import json

    print(json.dumps(bench_cmd_to_wire(int(os.environ.get("EMOS_BENCH_COMMANDS", "300")))))
