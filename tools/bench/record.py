"""``emos bench record``: what `emos record` costs the camera topic's other subscribers.

One system (the sensor demo's camera, 640x480 RGB at 30 Hz, and a probe that logs every frame's
publish-to-receive latency) runs throughout. Windows without and with a recorder (``emos record``
of all topics, to a file) alternate, A B then B A, so drift in the machine's load hits both
sides alike; each pair gives a ratio of the with/without latency percentiles.
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import psutil

from emos.tools.bench.common import percentiles, table
from emos.tools.bench.restart import _wait_for_run

SYSTEM = Path(__file__).with_name("record_system.py")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--pairs", type=int, default=4, help="A/B window pairs (default 4)")
    parser.add_argument("--window", type=float, default=6.0, help="seconds per window (default 6)")
    parser.add_argument("--compression", choices=("none", "zstd", "lz4"), default="none")
    parser.add_argument("--nice", type=int, default=0, help="pass --nice to emos record")
    parser.add_argument("--idle", action="store_true", help="pass --idle to emos record (SCHED_IDLE)")
    parser.add_argument("--defer-ms", type=float, default=None, help="pass --defer-ms to emos record (default: its default)")
    parser.add_argument("--against", choices=("record", "hz"), default="record",
                        help="what runs in the 'on' windows: the recorder, or (a control) `emos topic hz` on the camera, a subscriber that only reads")
    parser.add_argument("--bag-dir", default=None, help="where the recorder writes (default: a temporary directory on disk)")
    parser.add_argument("--json", action="store_true")


def _latencies(path: Path, t0: float, t1: float) -> np.ndarray:
    rows = [line.split() for line in path.read_text().splitlines() if line.strip()]
    return np.array([float(lat) for t, lat in rows if t0 <= float(t) < t1])


def _wait_recording(proc: subprocess.Popen, bag: Path | None, timeout: float = 30.0) -> None:
    """Keep the subscriber's start-up (imports: seconds of CPU on a loaded machine) out of the window:
    wait until the recorder has written its first chunk, then one more second."""
    end = time.monotonic() + timeout
    while bag is not None and not (bag.exists() and bag.stat().st_size > 1_000_000):
        if proc.poll() is not None or time.monotonic() > end:
            raise RuntimeError(f"the recorder did not start recording within {timeout} s (exit code {proc.poll()})")
        time.sleep(0.05)
    time.sleep(1.0 if bag is not None else 3.0)


def _recorded_frames(bag: Path) -> tuple[int, int]:
    """(frames in the file, frames the camera published between the first and the last of them)."""
    from emos.interop.mcap_read import read_bag

    seqs = [int(m.decode().header.frame_id) for m in read_bag(bag, topics=["/camera/rgb"])]
    return len(seqs), (max(seqs) - min(seqs) + 1 if seqs else 0)


def run(args: argparse.Namespace) -> int:
    if args.pairs < 1 or args.window <= 0:
        print("emos bench record: --pairs must be >= 1 and --window > 0")
        return 2
    work = Path(tempfile.mkdtemp(prefix="emos-bench-record-"))
    # The probe's log lives in tmpfs: a file on the disk the recorder fills would make the
    # probe's own writes wait for writeback, and measure that instead of the topic.
    fd, lat_name = tempfile.mkstemp(prefix="emos-bench-record-", suffix=".txt", dir="/dev/shm")
    os.close(fd)
    lat_file = Path(lat_name)
    env = dict(os.environ, EMOS_BENCH_LATENCY_FILE=str(lat_file))
    system = subprocess.Popen([sys.executable, "-m", "emos", "run", str(SYSTEM)], env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    windows: list[dict] = []
    try:
        run_id = _wait_for_run(system.pid).name
        time.sleep(3.0)  # components up and warm
        for i in range(args.pairs):
            for mode in (("off", "on") if i % 2 == 0 else ("on", "off")):
                rec, bag = None, Path(args.bag_dir or work) / f"emos-bench-record-{os.getpid()}.mcap"
                if mode == "on":
                    if args.against == "record":
                        cmd = ["record", "--run", run_id, "-o", str(bag), "--force", "-q", "--compression", args.compression, "--nice", str(args.nice)] + (["--idle"] if args.idle else [])
                        if args.defer_ms is not None:
                            cmd += ["--defer-ms", str(args.defer_ms)]
                    else:
                        cmd = ["topic", "hz", "--run", run_id, "/camera/rgb", "--window", "1"]
                    rec = subprocess.Popen([sys.executable, "-m", "emos", *cmd], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
                    _wait_recording(rec, bag if args.against == "record" else None)
                    cpu0 = psutil.Process(rec.pid).cpu_times()
                else:
                    time.sleep(0.5)
                t0 = time.time()
                time.sleep(args.window)
                t1 = time.time()
                row: dict[str, Any] = {"pair": i, "recorder": mode}
                if rec is not None:
                    cpu1 = psutil.Process(rec.pid).cpu_times()
                    row["recorder_cpu_pct"] = 100 * ((cpu1.user + cpu1.system) - (cpu0.user + cpu0.system)) / (t1 - t0)
                    rec.send_signal(signal.SIGTERM)
                    _, err = rec.communicate(timeout=30)
                    if rec.returncode not in (0, 128 + signal.SIGTERM, -signal.SIGTERM):
                        raise RuntimeError(f"emos {cmd[0]} failed ({rec.returncode}): {err.decode(errors='replace')}")
                    if args.against == "record":
                        row["bag_mb"] = bag.stat().st_size / 1e6
                        row["recorded"], row["published"] = _recorded_frames(bag)
                        bag.unlink()
                lat = _latencies(lat_file, t0, t1)
                row.update(n=len(lat), **percentiles(lat, (50, 90, 99)))
                windows.append(row)
    finally:
        system.send_signal(signal.SIGINT)
        try:
            system.wait(30)
        except subprocess.TimeoutExpired:
            system.kill()
            system.wait()
    ratios = []
    for i in range(args.pairs):
        off = next(w for w in windows if w["pair"] == i and w["recorder"] == "off")
        on = next(w for w in windows if w["pair"] == i and w["recorder"] == "on")
        ratios.append({"pair": i, "p50_ratio": on["p50"] / off["p50"], "p90_ratio": on["p90"] / off["p90"], "p99_ratio": on["p99"] / off["p99"]})
    summary = {key: {"median": float(np.median([r[key] for r in ratios])), "min": float(min(r[key] for r in ratios)),
                     "max": float(max(r[key] for r in ratios))} for key in ("p50_ratio", "p90_ratio", "p99_ratio")}
    result = {"bench": "record", "window_s": args.window, "pairs": args.pairs, "against": args.against, "compression": args.compression, "nice": args.nice, "idle": args.idle, "defer_ms": args.defer_ms, "bag_dir": args.bag_dir or "disk (temporary directory)",
              "windows": windows, "ratios": ratios, "summary": summary, "load_avg": os.getloadavg()}
    lat_file.unlink(missing_ok=True)
    work.rmdir()
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    print(table(windows, [("pair", "pair", "d"), ("recorder", "recorder", "s"), ("n", "frames", "d"), ("p50", "p50 ms", ".2f"),
                          ("p90", "p90 ms", ".2f"), ("p99", "p99 ms", ".2f"), ("recorder_cpu_pct", "rec CPU %", ".0f"), ("bag_mb", "bag MB", ".0f"), ("recorded", "frames in bag", "d"), ("published", "of published", "d")]))
    print()
    print(table(ratios, [("pair", "pair", "d"), ("p50_ratio", "p50 on/off", ".3f"), ("p90_ratio", "p90 on/off", ".3f"), ("p99_ratio", "p99 on/off", ".3f")]))
    for key, s in summary.items():
        print(f"{key}: median {s['median']:.3f}  (min {s['min']:.3f}, max {s['max']:.3f})")
    print(f"load average during the run: {result['load_avg'][0]:.2f}")
    return 0
