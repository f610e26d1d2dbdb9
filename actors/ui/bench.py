"""``emos bench ui``: the web UI watched live in headless Chromium, and what it costs the robot.

Phases, in one running system (see ``bench_system.py``): first no page open, then the page open
in headless Chromium. Measured: frames shown per second in the page, publish -> displayed
latency (the page compares each frame's header stamp with its clock when the frame is on the
canvas; same machine, same clock), and the camera's latency to another subscriber in both
phases (the UI must not slow the robot's topics down).
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from emos.supervisor.bench.common import percentiles, table

SYSTEM = Path(__file__).with_name("bench_system.py")
CHROME_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                "--disable-background-networking", "--disable-component-update", "--disable-sync", "--window-size=1400,1000")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.epilog = "examples:\n  emos bench ui\n  emos bench ui --duration 20 --json\n  emos bench ui --plot ui_latency.png\n"
    parser.add_argument("--duration", type=float, default=15.0, help="seconds measured in each phase (default: %(default)s)")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    parser.add_argument("--plot", metavar="FILE", help="save the latency distributions as a picture (PNG, SVG or PDF)")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait_port(port: int, proc: subprocess.Popen, timeout: float = 60.0) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if proc.poll() is not None:
            raise RuntimeError(f"the benchmark system exited with code {proc.returncode}")
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=1.0):
                return
        except OSError:
            time.sleep(0.2)
    raise TimeoutError(f"the UI did not listen on port {port} within {timeout} s")


def _browser() -> Any:
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
    except ImportError:
        raise SystemExit("emos bench ui needs selenium (pip install 'emos[test]') and chromium + chromium-driver (scripts/setup.sh --test)")
    chromium, driver = shutil.which("chromium") or "/usr/bin/chromium", shutil.which("chromedriver") or "/usr/bin/chromedriver"
    if not (os.path.exists(chromium) and os.path.exists(driver)):
        raise SystemExit("emos bench ui needs Debian's chromium and chromium-driver (scripts/setup.sh --test)")
    options = webdriver.ChromeOptions()
    for flag in CHROME_FLAGS:
        options.add_argument(flag)
    profile = tempfile.mkdtemp(prefix="emos-bench-chromium-")
    options.add_argument(f"--user-data-dir={profile}")
    options.binary_location = chromium
    return webdriver.Chrome(options=options, service=Service(driver)), profile


def _probe(out: Path, t0: float, t1: float) -> list[float]:
    try:
        samples = json.loads(out.read_text())
    except (OSError, ValueError):
        return []
    return [lat for t, lat in samples if t0 <= t <= t1]


def _progress(text: str) -> None:
    print(f"emos bench ui: {text}", file=sys.stderr, flush=True)


def measure(duration: float) -> dict[str, Any]:
    tmp = Path(tempfile.mkdtemp(prefix="emos-bench-ui-"))
    out, port = tmp / "probe.json", _free_port()
    env = dict(os.environ, EMOS_BENCH_UI_PORT=str(port), EMOS_BENCH_UI_OUT=str(out), EMOS_HOME=str(tmp / "home"))
    proc = subprocess.Popen([sys.executable, "-m", "emos.supervisor.cli", "run", str(SYSTEM)], env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    driver = profile = None
    try:
        _progress(f"starting the system (camera 640x480 at 30 Hz, map 400x400 at 2 Hz), UI on port {port}")
        _wait_port(port, proc)
        time.sleep(3.0)
        _progress(f"phase 1/2: no page open, {duration:g} s")
        a0 = time.time()
        time.sleep(duration)
        a1 = time.time()
        _progress("phase 2/2: opening the page in headless Chromium")
        driver, profile = _browser()
        driver.get(f"http://127.0.0.1:{port}/")
        time.sleep(3.0)
        driver.execute_script("window.emosStats.latencies = []; window.emosStats.frames = {};")
        _progress(f"phase 2/2: page open, {duration:g} s")
        b0 = time.time()
        time.sleep(duration)
        page = driver.execute_script("return {frames: window.emosStats.frames, latencies: window.emosStats.latencies}")
        b1 = time.time()
        import psutil

        ui_cpu = None
        for child in psutil.Process(proc.pid).children(recursive=True):
            try:
                if child.cmdline()[:1] and "ui" == _component_of(child):
                    ui_cpu = child.cpu_percent(1.0)
            except psutil.Error:
                pass
    finally:
        if driver is not None:
            driver.quit()
            shutil.rmtree(profile, ignore_errors=True)
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
            try:
                proc.wait(20)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
    without, with_ui = _probe(out, a0, a1), _probe(out, b0, b1)
    shutil.rmtree(tmp, ignore_errors=True)
    shown = page["latencies"]
    return {
        "duration_s": duration,
        "page": {"camera_fps": page["frames"].get("/camera/rgb", 0) / (b1 - b0), "map_fps": page["frames"].get("/map", 0) / (b1 - b0),
                 "latency_ms": percentiles(shown), "latencies": shown},
        "probe_without_ui": {"fps": len(without) / (a1 - a0), "latency_ms": percentiles(without), "latencies": without},
        "probe_with_ui": {"fps": len(with_ui) / (b1 - b0), "latency_ms": percentiles(with_ui), "latencies": with_ui},
        "ui_cpu_percent": ui_cpu,
    }


def _component_of(proc: Any) -> str | None:
    """Component processes are forks of the recipe: tell the UI's apart by its listening socket."""
    try:
        return "ui" if any(c.status == "LISTEN" and c.laddr and c.laddr.ip == "127.0.0.1" for c in proc.net_connections("tcp")) else None
    except Exception:
        return None


def save_plot(result: dict[str, Any], path: str) -> None:
    from emos.supervisor.plotting import pyplot

    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8, 4.5))
    series = [("page: publish -> displayed", result["page"]["latencies"]), ("camera -> probe, no page open", result["probe_without_ui"]["latencies"]),
              ("camera -> probe, page open", result["probe_with_ui"]["latencies"])]
    top = max([np.percentile(v, 99) for _, v in series if v] + [1.0])
    bins = np.linspace(0, top, 60)
    for label, values in series:
        if values:
            ax.hist(values, bins=bins, histtype="step", linewidth=1.8, label=f"{label} (p95 {np.percentile(values, 95):.1f} ms)")
    ax.set_xlabel("latency (ms)")
    ax.set_ylabel("frames")
    ax.set_title(f"emos bench ui: 640x480 camera at 30 Hz, page shows {result['page']['camera_fps']:.1f} fps")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def run(args: argparse.Namespace) -> int:
    if args.duration <= 0:
        print("emos bench ui: --duration must be > 0 seconds", file=sys.stderr)
        return 2
    result = measure(args.duration)
    if args.plot:
        save_plot(result, args.plot)
        _progress(f"plot saved to {args.plot}")
    if args.json:
        print(json.dumps({k: ({kk: vv for kk, vv in v.items() if kk != "latencies"} if isinstance(v, dict) else v) for k, v in result.items()}, indent=2))
        return 0
    rows = [
        {"what": "page: camera shown", "fps": result["page"]["camera_fps"], **result["page"]["latency_ms"]},
        {"what": "page: map shown", "fps": result["page"]["map_fps"]},
        {"what": "probe, no page open", "fps": result["probe_without_ui"]["fps"], **result["probe_without_ui"]["latency_ms"]},
        {"what": "probe, page open", "fps": result["probe_with_ui"]["fps"], **result["probe_with_ui"]["latency_ms"]},
    ]
    print(table(rows, [("what", "", "s"), ("fps", "frames/s", ".1f"), ("p50", "p50 ms", ".1f"), ("p95", "p95 ms", ".1f"), ("p99", "p99 ms", ".1f")]))
    if result["ui_cpu_percent"] is not None:
        print(f"UI process CPU with the page open: {result['ui_cpu_percent']:.0f} % of one core")
    return 0
