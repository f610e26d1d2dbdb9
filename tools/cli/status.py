"""``emos status``: the live supervision tree of a running system."""
from __future__ import annotations

import argparse
import json
import time
from typing import Any

import psutil

from emos.core.discovery import printable
from emos.core.rpc import RpcClient
from emos.tools.cli.common import add_run_argument, join_run


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_run_argument(parser)
    parser.add_argument("--json", action="store_true", help="print the tree as JSON")
    parser.add_argument("--watch", type=float, default=0.0, metavar="S", help="refresh every S seconds")
    parser.add_argument("--remote", metavar="ZENOH_CONFIG", nargs="?", const="", default=None,
                        help="the runs of every host in the Zenoh group ($EMOS_NET_GROUP) that were started with --zenoh, "
                             "through this Zenoh configuration file (default: $EMOS_ZENOH_CONFIG; with neither, only the "
                             "loopback sessions of this host and user); needs no local run")


def _cpu_percent(pids: list[int], interval: float = 0.25) -> dict[int, float]:
    procs = {}
    for pid in pids:
        try:
            p = psutil.Process(pid)
            p.cpu_percent(None)
            procs[pid] = p
        except psutil.Error:
            pass
    time.sleep(interval)
    out = {}
    for pid, p in procs.items():
        try:
            out[pid] = p.cpu_percent(None)
        except psutil.Error:
            pass
    return out


def _rows(node: dict[str, Any], depth: int = 0) -> list[tuple[int, dict[str, Any]]]:
    rows = [(depth, node)]
    for child in node.get("children", []):
        rows.extend(_rows(child, depth + 1))
    return rows


def snapshot(ctx_run: Any) -> dict[str, Any]:
    with RpcClient(ctx_run.run_dir / "supervisor.sock", timeout=5.0) as rpc:
        data = rpc.call("tree")
    workers = [n for _, n in _rows(data["tree"]) if n.get("kind") == "worker" and n.get("pid") and n.get("mode") == "process"]
    cpu = _cpu_percent([w["pid"] for w in workers])
    for w in workers:
        w["cpu_percent"] = cpu.get(w["pid"])
    return data


def render(data: dict[str, Any]) -> str:
    starting = "" if data.get("up", True) else "  (starting: later groups are not up yet)"
    lines = [f"run {data['run_id']}  supervisor pid {data['pid']}  up {data['uptime_s']:.1f} s{starting}", ""]
    # RESTARTS: over the whole run (group restarts included); LAST RESTART: why the last one was.
    header = (f"{'NAME':<28} {'PID':>7} {'STATE':<12} {'HEALTH':<18} {'RESTARTS':>8} {'UPTIME':>9} {'CPU%':>6} {'RSS MB':>7}  "
              f"{'LAST RESTART':<14}")
    lines.append(header)
    lines.append("-" * len(header))
    for depth, n in _rows(data["tree"]):
        name = "  " * depth + n.get("name", "?")
        last = _text(n.get("last_restart_reason")) or "-"
        if n.get("kind") == "supervisor":
            lines.append(f"{name:<28} {'':>7} {n.get('strategy', ''):<12} {n.get('intensity', ''):<18} {n.get('restarts', 0):>8} "
                         f"{'':>9} {'':>6} {'':>7}  {last:<14}")
            continue
        cpu = n.get("cpu_percent")
        lines.append(
            f"{name:<28} {n.get('pid') or '-':>7} {n.get('state', '?'):<12} {n.get('health', '?'):<18} {n.get('restarts', 0):>8} "
            f"{n.get('uptime_s', 0):>8.1f}s {'' if cpu is None else f'{cpu:.1f}':>6} {n.get('rss_mb', ''):>7}  {last:<14}"
        )
    return "\n".join(line.rstrip() for line in lines)


def _text(value: Any) -> str:
    """A reason from the tree answer (possibly another host's, over Zenoh) as plain printable text."""
    return printable(value, 40) if value else ""


def _remote(args: argparse.Namespace) -> int:
    from emos.transport.zenoh_net import close_sessions
    from emos.transport.zenoh_status import remote_status

    try:
        while True:
            runs = remote_status(args.remote or None)
            if args.json:
                print(json.dumps(runs, indent=2), flush=True)
            elif not runs:
                print("no run of this Zenoh group answered", flush=True)
            else:
                print("\n\n".join(f"{d['key']}\n{render(d)}" for d in runs), flush=True)
            if not args.watch:
                return 0 if runs else 1
            time.sleep(args.watch)
            print()
    finally:
        close_sessions()


def run(args: argparse.Namespace) -> int:
    if getattr(args, "remote", None) is not None:
        return _remote(args)
    ctx = join_run(args.run)
    while True:
        data = snapshot(ctx)
        print(json.dumps(data, indent=2) if args.json else render(data), flush=True)
        if not args.watch:
            return 0
        time.sleep(args.watch)
        print()
