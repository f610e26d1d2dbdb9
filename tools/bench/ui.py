"""``emos bench ui``: the web UI watched live in headless Chromium, and what it costs the robot.

Phases, in one running system (see ``ui_system.py``), alternating so that the load of other
work on the machine falls on both alike: no page open (the browser on about:blank), then the page
open in headless Chromium. Measured: frames shown per second in the page, publish -> displayed
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

from emos.actors.ui.auth import new_token
from emos.tools.bench.common import percentiles, table

SYSTEM = Path(__file__).with_name("ui_system.py")
CHROME_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                "--disable-background-networking", "--disable-component-update", "--disable-sync", "--window-size=1400,1000")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.epilog = "examples:\n  emos bench ui\n  emos bench ui --rounds 5 --duration 8 --json\n  emos bench ui --plot ui_latency.png\n"
    parser.add_argument("--duration", type=float, default=5.0, help="seconds measured in each phase (default: %(default)s)")
    parser.add_argument("--rounds", type=int, default=3, help="alternations of no page / page open (default: %(default)s)")
    parser.add_argument("--browser-nice", type=int, default=10, help="niceness of the browser, which shares the robot's cores here (default: %(default)s; 0 to keep it)")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    parser.add_argument("--https", action="store_true",
                        help="compare publish -> displayed over HTTPS (self-signed certificate) against HTTP: two systems, the page alternating between them")
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


def _browser(extra_flags: tuple[str, ...] = ()) -> tuple[Any, str]:
    """A headless Chromium driver and its temporary profile folder (the caller removes it)."""
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
    except ImportError:
        raise SystemExit("emos bench ui needs selenium (pip install 'emos[test]') and chromium + chromium-driver (scripts/setup.sh --test)") from None
    chromium, driver = shutil.which("chromium") or "/usr/bin/chromium", shutil.which("chromedriver") or "/usr/bin/chromedriver"
    if not (os.path.exists(chromium) and os.path.exists(driver)):
        raise SystemExit("emos bench ui needs Debian's chromium and chromium-driver (scripts/setup.sh --test)")
    options = webdriver.ChromeOptions()
    for flag in CHROME_FLAGS + tuple(extra_flags):
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


def _renice_browser(driver: Any, nice: int) -> None:
    """The page runs on a laptop in practice, not on the robot: here it shares the robot's cores,
    so it gets a lower priority than the components being measured."""
    import psutil

    try:
        for proc in psutil.Process(driver.service.process.pid).children(recursive=True):
            try:
                proc.nice(nice)
            except psutil.Error:
                pass
    except psutil.Error:
        pass


def measure(duration: float, rounds: int, browser_nice: int) -> dict[str, Any]:
    """Alternate ``rounds`` times between no page (the browser on about:blank) and the page, so
    that the load of other work on the machine falls on both alike."""
    import psutil

    tmp = Path(tempfile.mkdtemp(prefix="emos-bench-ui-"))
    out, port = tmp / "probe.json", _free_port()
    # The page needs the access token: give the system ours (its output is not read).
    token = new_token()
    env = dict(os.environ, EMOS_BENCH_UI_PORT=str(port), EMOS_BENCH_UI_OUT=str(out), EMOS_HOME=str(tmp / "home"), EMOS_UI_TOKEN=token)
    proc = subprocess.Popen([sys.executable, "-m", "emos.tools.cli", "run", "--no-log", str(SYSTEM)], env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    driver: Any = None
    profile: str | None = None
    off_windows, on_windows, shown, frames, maps, ui_cpu = [], [], [], 0, 0, []
    try:
        _progress(f"starting the system (camera 640x480 at 30 Hz, map 400x400 at 2 Hz), UI on port {port}")
        _wait_port(port, proc)
        driver, profile = _browser()
        if browser_nice:
            _renice_browser(driver, browser_nice)
        driver.get("about:blank")
        ui = next((p for p in psutil.Process(proc.pid).children(recursive=True) if _component_of(p) == "ui"), None)
        time.sleep(2.0)
        for r in range(rounds):
            _progress(f"round {r + 1}/{rounds}: no page, {duration:g} s")
            t0 = time.time()
            time.sleep(duration)
            off_windows.append((t0, time.time()))
            _progress(f"round {r + 1}/{rounds}: page open, {duration:g} s")
            driver.get(f"http://127.0.0.1:{port}/?token={token}")  # the server moves it into a cookie
            time.sleep(2.0)  # connect and first frames, not measured
            if browser_nice:
                _renice_browser(driver, browser_nice)  # renderers started for the page
            driver.execute_script("window.emosStats.latencies = []; window.emosStats.frames = {};")
            if ui is not None:
                ui.cpu_percent(None)
            t0 = time.time()
            time.sleep(duration)
            page = driver.execute_script("return {frames: window.emosStats.frames, latencies: window.emosStats.latencies}")
            t1 = time.time()
            if ui is not None:
                ui_cpu.append(ui.cpu_percent(None))
            on_windows.append((t0, t1))
            shown += page["latencies"]
            frames += page["frames"].get("/camera/rgb", 0)
            maps += page["frames"].get("/map", 0)
            driver.get("about:blank")
    finally:
        if driver is not None:
            driver.quit()
        if profile is not None:  # set with the driver, by _browser
            shutil.rmtree(profile, ignore_errors=True)
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
            try:
                proc.wait(20)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
    without = [x for a, b in off_windows for x in _probe(out, a, b)]
    with_ui = [x for a, b in on_windows for x in _probe(out, a, b)]
    shutil.rmtree(tmp, ignore_errors=True)
    on_time = sum(b - a for a, b in on_windows)
    off_time = sum(b - a for a, b in off_windows)
    return {
        "duration_s": duration, "rounds": rounds, "browser_nice": browser_nice,
        "page": {"camera_fps": frames / on_time, "map_fps": maps / on_time, "latency_ms": percentiles(shown), "latencies": shown},
        "probe_without_ui": {"fps": len(without) / off_time, "latency_ms": percentiles(without), "latencies": without},
        "probe_with_ui": {"fps": len(with_ui) / on_time, "latency_ms": percentiles(with_ui), "latencies": with_ui},
        "ui_cpu_percent": float(np.mean(ui_cpu)) if ui_cpu else None,
    }


def _start_system(tmp: Path, name: str, https: bool) -> tuple[subprocess.Popen, int, str, Path]:
    """One benchmark system (its own probe file and home); (process, port, page address with the token, home)."""
    out, port, token, home = tmp / f"probe-{name}.json", _free_port(), new_token(), tmp / f"home-{name}"
    env = dict(os.environ, EMOS_BENCH_UI_PORT=str(port), EMOS_BENCH_UI_OUT=str(out), EMOS_HOME=str(home), EMOS_UI_TOKEN=token)
    flags = ["--ui-https"] if https else []
    proc = subprocess.Popen([sys.executable, "-m", "emos.tools.cli", "run", "--no-log", *flags, str(SYSTEM)], env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    return proc, port, f"{'https' if https else 'http'}://127.0.0.1:{port}/?token={token}", home


def _spki_pin(cert: Path) -> str:
    """base64 SHA-256 of the certificate's public key: Chromium trusts exactly that key."""
    import base64
    import hashlib

    from cryptography import x509
    from cryptography.hazmat.primitives import serialization

    key = x509.load_pem_x509_certificate(cert.read_bytes()).public_key()
    der = key.public_bytes(serialization.Encoding.DER, serialization.PublicFormat.SubjectPublicKeyInfo)
    return base64.b64encode(hashlib.sha256(der).digest()).decode()


def measure_https(duration: float, rounds: int, browser_nice: int) -> dict[str, Any]:
    """Publish -> displayed over HTTP and over HTTPS in one run: both systems run throughout (so
    the machine's load is the same for both) and the page alternates between them."""
    tmp = Path(tempfile.mkdtemp(prefix="emos-bench-ui-https-"))
    systems = {name: _start_system(tmp, name, name == "https") for name in ("http", "https")}
    driver: Any = None
    profile: str | None = None
    shown: dict[str, list[float]] = {"http": [], "https": []}
    frames = {"http": 0, "https": 0}
    try:
        _progress("starting two systems (camera 640x480 at 30 Hz, map 400x400 at 2 Hz): UI over HTTP and over HTTPS")
        for proc, port, _, _ in systems.values():
            _wait_port(port, proc)
        cert = systems["https"][3] / "ui" / "tls" / "ui-selfsigned.crt"
        driver, profile = _browser((f"--ignore-certificate-errors-spki-list={_spki_pin(cert)}",))
        for r in range(rounds):
            for name in ("http", "https") if r % 2 == 0 else ("https", "http"):
                _progress(f"round {r + 1}/{rounds}: page over {name.upper()}, {duration:g} s")
                driver.get(systems[name][2])
                time.sleep(2.0)  # connect and first frames, not measured
                if browser_nice:
                    _renice_browser(driver, browser_nice)
                driver.execute_script("window.emosStats.latencies = []; window.emosStats.frames = {};")
                time.sleep(duration)
                page = driver.execute_script("return {frames: window.emosStats.frames, latencies: window.emosStats.latencies, proto: location.protocol}")
                if page["proto"] != name + ":":
                    raise RuntimeError(f"emos bench ui: the page came over {page['proto']}, not {name}")
                shown[name] += page["latencies"]
                frames[name] += page["frames"].get("/camera/rgb", 0)
                driver.get("about:blank")
    finally:
        if driver is not None:
            driver.quit()
        if profile is not None:
            shutil.rmtree(profile, ignore_errors=True)
        for proc, _, _, _ in systems.values():
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
        for proc, _, _, _ in systems.values():
            try:
                proc.wait(20)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
        shutil.rmtree(tmp, ignore_errors=True)
    on_time = duration * rounds
    result: dict[str, Any] = {"duration_s": duration, "rounds": rounds, "browser_nice": browser_nice}
    for name in ("http", "https"):
        result[name] = {"camera_fps": frames[name] / on_time, "latency_ms": percentiles(shown[name]), "latencies": shown[name]}
    p95 = (result["http"]["latency_ms"].get("p95"), result["https"]["latency_ms"].get("p95"))
    result["https_p95_over_http"] = p95[1] / p95[0] if p95[0] and p95[1] else None
    return result


def _component_of(proc: Any) -> str | None:
    """Component processes are forks of the recipe: tell the UI's apart by its listening socket."""
    try:
        return "ui" if any(c.status == "LISTEN" and c.laddr and c.laddr.ip == "127.0.0.1" for c in proc.net_connections("tcp")) else None
    except Exception:
        return None


def save_plot(result: dict[str, Any], path: str) -> None:
    from emos.tools.plotting import pyplot

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
    if args.duration <= 0 or args.rounds < 1 or not 0 <= args.browser_nice <= 19:
        print("emos bench ui: --duration must be > 0 seconds, --rounds >= 1, --browser-nice in 0..19", file=sys.stderr)
        return 2
    from emos.tools.plotting import check_plot_argument

    check_plot_argument(args.plot)
    if args.https:
        compared = measure_https(args.duration, args.rounds, args.browser_nice)
        if args.json:
            print(json.dumps({k: ({kk: vv for kk, vv in v.items() if kk != "latencies"} if isinstance(v, dict) else v) for k, v in compared.items()}, indent=2))
            return 0
        print(table([{"what": f"page over {n.upper()}", "fps": compared[n]["camera_fps"], **compared[n]["latency_ms"]} for n in ("http", "https")],
                    [("what", "", "s"), ("fps", "frames/s", ".1f"), ("p50", "p50 ms", ".1f"), ("p95", "p95 ms", ".1f"), ("p99", "p99 ms", ".1f")]))
        ratio = compared["https_p95_over_http"]
        print(f"HTTPS p95 / HTTP p95: {ratio:.3f}" if ratio else "HTTPS p95 / HTTP p95: not measured (no frames)")
        print(f"({compared['rounds']} rounds of {compared['duration_s']:g} s on each, alternating; browser niceness {compared['browser_nice']})")
        return 0
    result = measure(args.duration, args.rounds, args.browser_nice)
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
    print(f"({result['rounds']} rounds of {result['duration_s']:g} s without and with the page; browser niceness {result['browser_nice']})")
    return 0
