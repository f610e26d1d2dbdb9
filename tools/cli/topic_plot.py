"""``emos topic plot TOPIC FIELD...``: numbers from a topic over time, live or saved.

Fields are paths into the message: ``data``, ``twist.linear.x``, ``pose.pose.position.y``,
``ranges[0]``. With ``--output FILE`` the plot is saved when the time is up (PNG, SVG, PDF, or
CSV for the numbers themselves); without it, a window shows it live (needs a display).
"""
from __future__ import annotations

import argparse
import csv
import math
import os
import re
import select
import sys
import time
from typing import Any

import attrs
import numpy as np

from emos.msgs import codec

EXAMPLES = """examples:
  emos topic plot /cmd_vel twist.linear.x twist.angular.z --duration 20 --output cmd.png
  emos topic plot /battery data --output battery.csv --duration 60
  emos topic plot /odom pose.pose.position.x pose.pose.position.y      # live window
"""

_STEP = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)|\[(\d+)\]")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.formatter_class = argparse.RawDescriptionHelpFormatter
    p.epilog = EXAMPLES
    p.add_argument("topic")
    p.add_argument("fields", nargs="+", help="numeric fields, e.g. data, twist.linear.x, ranges[0]")
    p.add_argument("--duration", type=float, default=10.0, help="seconds to record (default: %(default)s; live: the window shown)")
    p.add_argument("--output", "-o", metavar="FILE", help="save instead of showing: .png, .svg, .pdf or .csv")


def parse_field(path: str) -> list[str | int]:
    steps: list[str | int] = []
    for part in path.split("."):
        pos = 0
        for m in _STEP.finditer(part):
            if m.start() != pos:
                break
            steps.append(m.group(1) if m.group(1) else int(m.group(2)))
            pos = m.end()
        if pos != len(part) or not part:
            raise ValueError(f"field {path!r} is not a path like twist.linear.x or ranges[0]")
    return steps


def field_value(msg: Any, path: str, steps: list[str | int]) -> float:
    value = msg
    for step in steps:
        if isinstance(step, int):
            if not isinstance(value, (list, tuple, np.ndarray)) or step >= len(value):
                raise ValueError(f"{path}: index [{step}] does not exist (length {len(value) if hasattr(value, '__len__') else 'none'})")
            value = value[step]
        else:
            if not attrs.has(type(value)) or not hasattr(value, step):
                names = [f.name for f in attrs.fields(type(value))] if attrs.has(type(value)) else []
                raise ValueError(f"{path}: {type(value).__name__} has no field {step!r}" + (f"; fields: {', '.join(names)}" if names else ""))
            value = getattr(value, step)
    if isinstance(value, np.ndarray) and value.size != 1:
        raise ValueError(f"{path} is an array of {value.size}; pick one element, e.g. {path}[0]")
    if isinstance(value, (bool, int, float, np.generic, np.ndarray)):
        return float(value)
    raise ValueError(f"{path} is a {type(value).__name__}, not a number")


def _draw(plt: Any, ax: Any, topic: str, fields: list[str], t: list[float], series: list[list[float]]) -> None:
    ax.clear()
    for name, values in zip(fields, series):
        ax.plot(t, values, label=name, linewidth=1.5)
    ax.set_xlabel("time (s)")
    ax.set_title(topic)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left")


def run(args: argparse.Namespace, ctx: Any, topic: str, cls: type) -> int:
    from emos.transport.pubsub import Subscriber
    from emos.transport.waker import Waker

    if args.duration <= 0:
        print("emos topic plot: --duration must be > 0 seconds", file=sys.stderr)
        return 2
    try:
        paths = [(f, parse_field(f)) for f in args.fields]
    except ValueError as exc:
        print(f"emos topic plot: {exc}", file=sys.stderr)
        return 2
    out = args.output
    if out and os.path.splitext(out)[1].lower() not in (".png", ".svg", ".pdf", ".csv"):
        print(f"emos topic plot: --output must end in .png, .svg, .pdf or .csv, got {out!r}", file=sys.stderr)
        return 2
    live = out is None
    if live and not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
        print("emos topic plot: no display for a live plot here; save it with --output plot.png", file=sys.stderr)
        return 2
    plt: Any = None  # matplotlib.pyplot, imported only when a plot is drawn
    ax: Any = None
    if live or not out.endswith(".csv"):
        try:
            import matplotlib
        except ImportError:
            print("emos topic plot: plots need matplotlib: pip install 'emos[plots]'", file=sys.stderr)
            return 2
        if not live:
            matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(9, 4.5))
        if live:
            plt.ion()
            plt.show(block=False)
    waker = Waker(ctx)
    sub = Subscriber(ctx, topic, cls, waker=waker, queue_size=1000)
    t: list[float] = []
    series: list[list[float]] = [[] for _ in paths]
    t0 = None
    end = time.monotonic() + args.duration
    last_draw = 0.0
    print(f"emos topic plot: recording {', '.join(args.fields)} of {topic} for {args.duration:g} s", file=sys.stderr, flush=True)
    try:
        while time.monotonic() < end:
            select.select([waker.fd], [], [], 0.1)
            waker.drain()
            for stamp, raw, _ in sub.take_raw():
                msg = codec.decode(cls, raw, copy=True)
                t0 = stamp if t0 is None else t0
                try:
                    values = [field_value(msg, name, steps) for name, steps in paths]
                except ValueError as exc:
                    print(f"emos topic plot: {exc}", file=sys.stderr)
                    return 2
                t.append((stamp - t0) / 1e9)
                for s, v in zip(series, values):
                    s.append(v)
            if live and time.monotonic() - last_draw > 0.25:
                last_draw = time.monotonic()
                _draw(plt, ax, topic, args.fields, t, series)
                plt.pause(0.001)
    except KeyboardInterrupt:
        pass
    finally:
        sub.close()
        waker.close()
    if not t:
        print(f"emos topic plot: no message on {topic} in {args.duration:g} s", file=sys.stderr)
        return 1
    if out and out.endswith(".csv"):
        with open(out, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["t_s", *args.fields])
            w.writerows(zip(t, *series))
    elif out:
        _draw(plt, ax, topic, args.fields, t, series)
        fig.tight_layout()
        fig.savefig(out)
    for name, s in zip(args.fields, series):
        finite = [v for v in s if math.isfinite(v)]
        if finite:
            print(f"{name}: n={len(s)} min {min(finite):.6g} max {max(finite):.6g} last {s[-1]:.6g}")
    if out:
        print(f"saved {out}")
    return 0
