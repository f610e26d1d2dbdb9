"""Parse cost per RPLIDAR scan: ours against pyrplidar's, on the same byte stream (for
``emos bench hardware``; run ``python -m emos.actors.hardware.rplidar.bench`` meanwhile).

The stream is what the emulator sends: ``revolutions`` revolutions of 360 nodes (a room cast
around the sensor), cut into ``chunk``-byte reads as a serial port delivers them. Measured in CPU
seconds of this process (``time.process_time``), best of ``repeats``:

* ``ours_parse``: ``NodeParser.feed`` over the chunks (sync checks, resync, field decode);
* ``ours_full``: the same plus ``RevolutionAssembler`` and ``revolution_ranges`` (LaserScan
  arrays in the ROS convention): what the driver does per scan;
* ``pyrplidar``: ``PyRPlidarMeasurement(5 bytes)`` per node, which is what pyrplidar's
  ``start_scan`` generator does per node after its 5-byte read (it checks no sync bit and
  builds no scan, so this is its cost floor).

:func:`live_cost` measures the whole reading side instead: an emulator in a process of its own
(``python -m ...emulator``), then this process's CPU seconds while ``scans`` revolutions arrive,
once through our driver (reads, parse, revolutions, LaserScan arrays) and once through
pyrplidar's ``start_scan`` generator (a 5-byte read and a ``PyRPlidarMeasurement`` per node).
"""
from __future__ import annotations

import argparse
import json
import math
import time
from typing import Any

import numpy as np

from .protocol import ANGLE_Q6_FULL, NodeParser, encode_nodes
from .scan import RevolutionStream, revolution_ranges

__all__ = ["make_stream", "parse_cost"]


def make_stream(revolutions: int = 100, points: int = 360, seed: int = 0) -> bytes:
    """The bytes of ``revolutions`` standard-scan revolutions in a 6 x 4 m room."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(revolutions):
        cw_deg = rng.uniform(0, 360.0 / points) + np.arange(points) * (360.0 / points)
        b = -np.radians(cw_deg)
        with np.errstate(divide="ignore"):
            r = np.minimum(np.abs(3.0 / np.cos(b)), np.abs(2.0 / np.sin(b)))
        dist = np.clip(np.rint(r * 4000), 0, 0xFFFF)
        angle = np.minimum(np.rint(cw_deg * 64), ANGLE_Q6_FULL - 1)
        out.append(encode_nodes(np.arange(points) == 0, np.full(points, 40), angle, dist))
    return b"".join(out)


def _cpu(fn, repeats: int) -> float:
    best = math.inf
    for _ in range(repeats):
        t0 = time.process_time()
        fn()
        best = min(best, time.process_time() - t0)
    return best


def parse_cost(revolutions: int = 100, chunk: int = 512, repeats: int = 3) -> dict[str, Any]:
    """CPU seconds per scan for ours and pyrplidar's (module docstring), and their ratio."""
    stream = make_stream(revolutions)
    chunks = [stream[i:i + chunk] for i in range(0, len(stream), chunk)]

    def ours_parse() -> None:
        p = NodeParser(hold_until_start=True)  # as the driver runs it (RevolutionStream)
        for c in chunks:
            p.feed(c)

    def ours_full() -> None:
        stream = RevolutionStream()
        for c in chunks:
            for rev in stream.feed(c):
                revolution_ranges(rev.nodes, 360, 0.15, 12.0)

    result: dict[str, Any] = {"revolutions": revolutions, "bytes": len(stream), "chunk": chunk,
                              "ours_parse_us_per_scan": _cpu(ours_parse, repeats) / revolutions * 1e6,
                              "ours_full_us_per_scan": _cpu(ours_full, repeats) / revolutions * 1e6}
    try:
        from pyrplidar_protocol import PyRPlidarMeasurement  # type: ignore[import-untyped]
    except ImportError:
        result["pyrplidar_us_per_scan"] = None
        result["parse_cpu_ratio_vs_pyrplidar"] = None
        return result

    def theirs() -> None:
        for i in range(0, len(stream), 5):
            PyRPlidarMeasurement(stream[i:i + 5])

    result["pyrplidar_us_per_scan"] = _cpu(theirs, repeats) / revolutions * 1e6
    # pyrplidar's CPU over ours (> 1: ours is cheaper), parse against parse; and against our
    # whole per-scan work (parse + revolutions + LaserScan arrays), which pyrplidar does not do
    result["parse_cpu_ratio_vs_pyrplidar"] = result["pyrplidar_us_per_scan"] / result["ours_parse_us_per_scan"]
    result["full_cpu_ratio_vs_pyrplidar"] = result["pyrplidar_us_per_scan"] / result["ours_full_us_per_scan"]
    return result


def live_cost(scans: int = 30, map_yaml: str | None = None, against_pyrplidar: bool = True) -> dict[str, Any]:
    """CPU seconds per scan of this process reading a live emulator (module docstring);
    ``against_pyrplidar=False`` skips the second reading, by pyrplidar (``emos bench hardware``
    compares the parsers on the same byte stream instead: :func:`parse_cost`)."""
    import os
    import subprocess
    import sys

    from .driver import RplidarDriver

    if map_yaml is None:
        from emos.packages import get_package_share_directory

        map_yaml = os.path.join(get_package_share_directory("kompass_sim"), "maps", "turtlebot3_gazebo_house.yaml")
    proc = subprocess.Popen([sys.executable, "-m", "emos.actors.hardware.rplidar.emulator", "--map", map_yaml, "--pose", "0,0,0"],
                            stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None
        port = proc.stdout.readline().strip()
        if not port:
            raise RuntimeError(f"the RPLIDAR emulator printed no port (exit code {proc.poll()})")
        driver = RplidarDriver(port)
        driver.start()
        for _ in range(3):  # spin-up and the first (partial) revolutions
            driver.wait_scan(10.0)
        t0, w0 = time.process_time(), time.monotonic()
        got = 0
        while got < scans and driver.wait_scan(10.0) is not None:
            got += 1
        ours = (time.process_time() - t0) / max(got, 1)
        rate = got / (time.monotonic() - w0)
        corrupt = driver.corrupt_scans
        driver.stop()
        result: dict[str, Any] = {"scans": got, "scans_per_s": rate, "corrupt_scans": corrupt, "ours_live_us_per_scan": ours * 1e6}
        if not against_pyrplidar:
            return result
        try:
            from pyrplidar import PyRPlidar  # type: ignore[import-untyped]
        except ImportError:
            result["pyrplidar_live_us_per_scan"] = None
            return result
        import contextlib
        import io

        with contextlib.redirect_stdout(io.StringIO()):  # pyrplidar prints on connect
            lidar = PyRPlidar()
            lidar.connect(port=port, baudrate=115200, timeout=3)
            gen = lidar.start_scan()()
            seen = 0
            for m in gen:  # skip to the first start flag after the spin-up
                if m.start_flag:
                    seen += 1
                    if seen == 2:
                        break
            t0 = time.process_time()
            seen = 0
            for m in gen:
                if m.start_flag:
                    seen += 1
                    if seen == scans:
                        break
            theirs = (time.process_time() - t0) / scans
            lidar.stop()
            lidar.disconnect()
        result["pyrplidar_live_us_per_scan"] = theirs * 1e6
        result["live_cpu_ratio_vs_pyrplidar"] = theirs / ours
        return result
    finally:
        proc.terminate()
        proc.wait(10)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m emos.actors.hardware.rplidar.bench", description=__doc__.split("\n")[0])
    ap.add_argument("--revolutions", type=int, default=100)
    ap.add_argument("--chunk", type=int, default=512, help="bytes per read (the driver reads >= 512)")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--live", type=int, default=0, metavar="SCANS", help="also read SCANS scans from a live emulator process")
    args = ap.parse_args(argv)
    r = parse_cost(args.revolutions, args.chunk)
    if args.live:
        r.update(live_cost(args.live))
    if args.json:
        print(json.dumps(r))
    else:
        for k, v in r.items():
            print(f"{k:32s} {v if not isinstance(v, float) else f'{v:.1f}'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
