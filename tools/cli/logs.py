"""``emos logs``: the kept output of past ``emos run``s."""
from __future__ import annotations

import argparse
import sys
import time

from emos.supervisor.recipes import logs_dir
from emos.supervisor.runlog import list_logs

EXAMPLES = """examples:
  emos logs                  # list the kept logs, newest last
  emos logs --last           # print the newest log
  emos logs ui_demo          # print the newest log of the ui_demo recipe
  emos logs ui_demo_20260101-120000.log --follow
"""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.formatter_class = argparse.RawDescriptionHelpFormatter
    parser.epilog = EXAMPLES
    parser.add_argument("log", nargs="?", help="a log file name, or a recipe name for its newest log")
    parser.add_argument("--last", action="store_true", help="the newest log of any recipe")
    parser.add_argument("--follow", "-f", action="store_true", help="keep printing as the log grows (Ctrl-C to stop)")
    parser.add_argument("--tail", "-n", type=int, default=0, help="print only the last N lines")


def run(args: argparse.Namespace) -> int:
    logs = list_logs()
    if not args.log and not args.last:
        if not logs:
            print(f"no logs yet in {logs_dir()} (every `emos run` keeps one)")
            return 0
        print(f"logs in {logs_dir()}:")
        for p in logs:
            st = p.stat()
            print(f"  {p.name:<48} {time.strftime('%Y-%m-%d %H:%M', time.localtime(st.st_mtime))}  {st.st_size / 1024:8.1f} KiB")
        return 0
    if args.last:
        chosen = logs[-1] if logs else None
    else:
        chosen = next((p for p in logs if p.name == args.log or p.name == args.log + ".log"), None)
        if chosen is None:
            mine = [p for p in logs if p.name.rsplit("_", 2)[0] == args.log]
            chosen = mine[-1] if mine else None
    if chosen is None:
        print(f"emos logs: no log {args.log or ''!r} in {logs_dir()}; `emos logs` lists them", file=sys.stderr)
        return 2
    with open(chosen, errors="replace") as f:
        lines = f.readlines()
        sys.stdout.writelines(lines[-args.tail:] if args.tail > 0 else lines)
        sys.stdout.flush()
        if args.follow:
            try:
                while True:
                    line = f.readline()
                    if line:
                        sys.stdout.write(line)
                        sys.stdout.flush()
                    else:
                        time.sleep(0.2)
            except KeyboardInterrupt:
                pass
    return 0
