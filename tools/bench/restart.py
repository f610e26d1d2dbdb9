"""``emos bench restart --kills N``: SIGKILL a running component N times.

Detection is kill -> the supervisor's pidfd fires (its event log records that instant on the
shared monotonic clock); recovery is kill -> the new process publishes on its topic again.
After the run: zombies among the system's processes and shared-memory segments left behind.
"""
from __future__ import annotations

import argparse
import json
import os
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

import psutil

from emos.core.rpc import RpcClient
from emos.msgs import Int64
from emos.tools.bench.common import percentiles
from emos.transport.context import SHM_DIR, RunContext, runtime_root
from emos.transport.pubsub import Subscriber
from emos.transport.waker import Waker

SYSTEM = Path(__file__).with_name("restart_system.py")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--kills", type=int, default=200)
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--plot", metavar="FILE", help="save the detect and recover time distributions as a picture (.png, .svg, .pdf)")
    parser.add_argument("--timeout", type=float, default=10.0, help="seconds to wait for one recovery")


def _wait_for_run(pid: int, timeout: float = 30.0) -> Path:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        for d in runtime_root().iterdir():
            if d.name.startswith(f"{pid}-") and (d / "supervisor.sock").exists():
                return d
        time.sleep(0.05)
    raise TimeoutError(f"system pid {pid} did not come up within {timeout} s")


def _victim_pid(rpc: RpcClient) -> int | None:
    tree = rpc.call("tree")["tree"]
    for group in tree["children"]:
        for child in group.get("children", []):
            if child.get("name") == "victim":
                return child.get("pid")
    return None


def run(args: argparse.Namespace) -> int:
    if args.kills < 1:
        print("emos bench restart: --kills must be >= 1")
        return 2
    from emos.tools.plotting import check_plot_argument

    check_plot_argument(args.plot)
    env = dict(os.environ, EMOS_BENCH_KILLS=str(args.kills))
    system = subprocess.Popen([sys.executable, "-m", "emos", "run", "--no-log", str(SYSTEM)], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    detect_ms: list[float] = []
    recover_ms: list[float] = []
    try:
        run_dir = _wait_for_run(system.pid)
        ctx = RunContext(run_dir.name, run_dir, owner=False)
        rpc = RpcClient(run_dir / "supervisor.sock")
        waker = Waker(ctx)
        sub = Subscriber(ctx, "/victim/data", Int64, waker=waker, queue_size=256)

        def next_pid_message(not_pid: int | None, deadline: float) -> int:
            while time.monotonic() < deadline:
                select.select([waker.fd], [], [], 0.05)
                waker.drain()
                for msg in sub.take():
                    if msg.data != not_pid:
                        return msg.data
            raise TimeoutError("no message from a new victim process")

        pid = next_pid_message(None, time.monotonic() + 30)
        segments_running = len(ctx.all_segments())
        for i in range(args.kills):
            pid = _victim_pid(rpc) or pid
            sub.take()
            t_kill = time.monotonic()
            os.kill(pid, signal.SIGKILL)
            new_pid = next_pid_message(pid, t_kill + args.timeout)
            recover_ms.append((time.monotonic() - t_kill) * 1e3)
            exits = [e for e in rpc.call("events", since=t_kill) if e["event"] == "exit" and e["child"] == "victim"]
            if exits:
                detect_ms.append((exits[0]["detected_at"] - t_kill) * 1e3)
            pid = new_pid
            if not args.json and (i + 1) % max(1, args.kills // 10) == 0:
                print(f"  {i + 1}/{args.kills} kills: recover p50 {percentiles(recover_ms)['p50']:.1f} ms", flush=True)
        zombies = sum(1 for p in psutil.Process(system.pid).children(recursive=True) if p.status() == psutil.STATUS_ZOMBIE)
        segments_after_kills = len(ctx.all_segments())
        sub.close()
        waker.close()
        rpc.call("stop", reason="benchmark finished")
        rpc.close()
        system.wait(30)
    finally:
        if system.poll() is None:
            system.kill()
            system.wait()
    leaked = sum(1 for n in os.listdir(SHM_DIR) if n.startswith(ctx.shm_prefix)) + (1 if run_dir.exists() else 0)
    orphans = [p.pid for p in psutil.process_iter(["name"]) if (p.info["name"] or "").startswith("emos:victim")]
    d, r = percentiles(detect_ms, (50, 95)), percentiles(recover_ms, (50, 95))
    result = {
        "kills": args.kills,
        "detect_ms": {"p50": round(d["p50"], 3), "p95": round(d["p95"], 3)},
        "recover_ms": {"p50": round(r["p50"], 3), "p95": round(r["p95"], 3)},
        "leaked_shm": leaked,
        "zombies": zombies + len(orphans),
    }
    if args.plot:
        from emos.tools.plotting import save_histograms

        save_histograms(args.plot, f"emos bench restart: {args.kills} kills", "ms", {"kill -> detected": detect_ms, "kill -> publishing again": recover_ms})
    if args.json:
        print(json.dumps(result))
    else:
        print(f"kills {args.kills}: detect p50 {d['p50']:.2f} ms p95 {d['p95']:.2f} ms; recover p50 {r['p50']:.1f} ms p95 {r['p95']:.1f} ms")
        print(f"segments while running: {segments_running} before kills, {segments_after_kills} after; left after exit: {leaked}; zombies/orphans: {zombies + len(orphans)}")
    return 0 if system.returncode == 0 else 1
