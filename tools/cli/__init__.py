"""The ``emos`` command line.

Subcommands live in their own modules and are loaded lazily, so ``emos status`` never pays for
importing pybullet or torch. Each plug-in module exposes ``add_arguments(parser)`` and
``run(args) -> int`` (the exit code).
"""
from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys

# name -> (module, one-line help). Modules are imported only when their command runs.
COMMANDS: dict[str, tuple[str, str]] = {
    "run": ("emos.tools.cli.run", "run a recipe script under the supervisor"),
    "status": ("emos.tools.cli.status", "show the live supervision tree of a running system"),
    "topic": ("emos.tools.cli.topic", "list, echo, measure or publish topics"),
    "chaos": ("emos.tools.cli.chaos", "inject faults into a running recipe and check that it recovers"),
    "ls": ("emos.tools.cli.ls", "list the recipes on this machine"),
    "info": ("emos.tools.cli.info", "show the sensors and topics a recipe needs, without running it"),
    "logs": ("emos.tools.cli.logs", "list the logs of past runs, or show one"),
    "service": ("emos.tools.cli.service", "run a recipe as a systemd service (create, remove, status); call or list components' services"),
    "action": ("emos.tools.cli.action", "list components' actions, or send one a goal: feedback as it comes, Ctrl-C cancels it"),
    "version": ("emos.tools.cli.version", "show the EMOS version"),
    "component": ("emos.tools.cli.component", "list components, show one, or call its reconfiguration services"),
    "record": ("emos.tools.cli.record", "record a running system's topics into an MCAP file"),
    "play": ("emos.tools.cli.play", "publish an MCAP recording into a running system, with its timing"),
    "map": ("emos.tools.cli.map", "build a map from a recording (offline SLAM) or draw a saved one"),
    "viz": ("emos.tools.cli.viz", "serve a running system's topics to Foxglove over its WebSocket protocol"),
    "ui": ("emos.tools.cli.ui", "the web UI's paired devices: list (tokens) or revoke their tokens, show the pairing code (pair)"),
    "security": ("emos.tools.cli.security", "keystore (CA), identities, and Zenoh TLS + access rules derived from a recipe"),
    "robot": ("emos.tools.cli.robot", "list robot plugins, or inspect one: topics, actions, events, transports, config"),
}

# `emos bench NAME`: one module per benchmark, all in the tools tier (emos.tools.bench).
BENCHMARKS: dict[str, tuple[str, str]] = {
    "ipc": ("emos.tools.bench.ipc", "shared-memory topic latency and throughput vs multiprocessing"),
    "net": ("emos.tools.bench.net", "topic latency between two runs over Zenoh: EMOS against raw eclipse-zenoh"),
    "ros2": ("emos.tools.bench.ros2", "half round trips rclpy <-> rclpy and EMOS component <-> rclpy node through the ROS 2 bridge"),
    "restart": ("emos.tools.bench.restart", "kill-to-detect and kill-to-recover times of the supervisor"),
    "events": ("emos.tools.bench.events", "event-to-action and failure-to-fallback latencies"),
    "record": ("emos.tools.bench.record", "camera latency to its subscribers with and without `emos record`"),
    "nav": ("emos.tools.bench.nav", "navigation algorithm kernels: costs, mapping, safety, DWA, planners"),
    "localize": ("emos.tools.bench.localize", "Monte Carlo localization on real lidar logs (CARMEN): tracking and global"),
    "navloop": ("emos.tools.bench.navloop", "scan to motor command through LocalMapper, Controller and DriveManager processes"),
    "sim": ("emos.tools.bench.sim", "simulation speed relative to real time"),
    "barn": ("emos.tools.barn", "BARN navigation benchmark"),
    "agents": ("emos.tools.bench.agents", "semantic routing and vector-store query times"),
    "llm": ("emos.tools.bench.local_llm", "local SmolLM2 (llama.cpp): tokens/s and first token in-component vs server; fallback_to_local swap"),
    "ui": ("emos.tools.bench.ui", "web UI in headless Chromium: frames shown, display latency, cost to other subscribers"),
    "slam": ("emos.tools.bench.slam", "graph SLAM on a real lidar log (CARMEN): trajectory error, CPU per scan, the map"),
    "cortex": ("emos.tools.bench.cortex", "Cortex planning on 20 house tasks: success, steps, replans, time per planning step"),
    "hardware": ("emos.tools.bench.hardware", "drivers on emulated devices: /cmd_vel to wire, lidar scans and parse CPU, servo cycle"),
    "costmap": ("emos.tools.bench.costmap", "keepout zones on the shortest routes in the house: entries (goal 0), planner time with/without costmap"),
}

# `emos serve NAME`: long-running development services.
SERVICES: dict[str, tuple[str, str]] = {
    "models": ("emos.actors.agents.server.cli", "local OpenAI- and Ollama-compatible model server"),
}


# Examples for `--help` of commands whose modules do not give their own (``parser.epilog``).
EXAMPLES: dict[str, str] = {
    "run": "emos run ui_demo                      # a recipe by name (see `emos ls`)\n"
           "emos run recipes/sensor_demo.py --duration 20\n"
           "emos run --duration 30 ui_demo -- --port 5002   # arguments after -- go to the recipe",
    "status": "emos status\nemos status --watch 1\nemos status --json --run 1234-5678",
    "topic": "emos topic list\nemos topic echo /odom -n 1\nemos topic hz /camera/rgb\n"
             "emos topic pub /goal PoseStamped '{\"pose\": {\"position\": {\"x\": 1.0}}}'\n"
             "emos topic plot /cmd_vel twist.linear.x --duration 20 --output cmd.png",
    "bench ipc": "emos bench ipc\nemos bench ipc --sizes 64,921600 --json\nemos bench ipc --plot ipc.png",
    "bench restart": "emos bench restart --kills 50\nemos bench restart --kills 200 --plot restart.png",
    "bench nav": "emos bench nav\nemos bench nav --json",
    "bench localize": "emos bench localize --log ../shared/benchmarks/radish/intel-corrected.log.gz --seeds 5\n"
                      "emos bench localize --log aces-corrected.log.gz --global --seeds 20 --json",
    "bench sim": "emos bench sim\nemos bench sim --json",
    "bench barn": "emos bench barn\nemos bench barn --json\nemos bench barn --generate 30 --seed 7 --seeds 1",
    "bench agents": "emos bench agents\nemos bench agents --json",
    "bench slam": "emos bench slam --log ../shared/benchmarks/radish/intel-corrected.log.gz\n"
                  "emos bench slam --log orebro-corrected.log.gz --seed 1 --json\n"
                  "emos bench slam --log intel-corrected.log.gz --map intel.yaml --plot intel_slam.png",
    "serve models": "emos serve models\nemos serve models --help   # address and models",
    "record": "emos record -o run.mcap                  # every topic, until Ctrl-C\n"
              "emos record /camera/rgb /scan -o two.mcap --duration 10\n"
              "emos record -o nav.mcap -x '/*/status' --compression zstd",
    "play": "emos play run.mcap\nemos play run.mcap --rate 2 --loop --topics /scan",
    "map": "emos record /scan /odom -o run.mcap      # drive the robot, Ctrl-C\n"
           "emos map build run.mcap -o office         # office.yaml + office.pgm\n"
           "emos map show office.yaml                 # office.png",
    "viz": "emos viz                                  # ws://127.0.0.1:8765 for Foxglove\nemos viz /scan '/camera/*' --port 8766\n"
           "emos viz --token auto                     # prints the URL with its token once",
    "bench record": "emos bench record\nemos bench record --pairs 4 --window 8 --against hz   # control",
    "robot": "emos robot list\nemos robot inspect create2\nemos robot inspect mypkg.base:MyBase --json",
    "bench hardware": "emos bench hardware\nemos bench hardware --json\nemos bench hardware --commands 1000 --scans 100",
}


def _add_plugin(sub: argparse._SubParsersAction, name: str, module: str, help_text: str) -> None:
    parser = sub.add_parser(name, help=help_text, description=help_text)
    parser.set_defaults(_module=module)
    # Arguments are added only for the command actually chosen (see main): importing every
    # plug-in just to print help would import pybullet, torch and chromadb.
    parser.set_defaults(_needs_args=True)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="emos", description="EMOS, the Embodied Operating System")
    sub = parser.add_subparsers(dest="command", required=True)
    for name, (module, help_text) in COMMANDS.items():
        _add_plugin(sub, name, module, help_text)
    for group, table, help_text in (
        ("bench", BENCHMARKS, "run a benchmark"),
        ("serve", SERVICES, "run a development service"),
    ):
        group_parser = sub.add_parser(group, help=help_text, description=help_text)
        group_sub = group_parser.add_subparsers(dest=f"{group}_name", required=True)
        for name, (module, help_text) in table.items():
            _add_plugin(group_sub, name, module, help_text)
    return parser


def _chosen_path(argv: list[str]) -> list[str]:
    """The command words (``bench ipc``) before the first option."""
    words = []
    for word in argv:
        if word.startswith("-"):
            break
        words.append(word)
        if word not in ("bench", "serve"):
            break
    return words


def _terminated(signum: int, frame: object) -> None:
    # SIGTERM unwinds like Ctrl-C, so every command's `finally` releases what it holds (a
    # topic's ring, a wake-up FIFO, benchmark children); 143 = 128 + SIGTERM. Noted first, for
    # the loops that check it should this SystemExit land where Python swallows it.
    # No import here: a SIGTERM that lands while the command's modules are being imported would
    # import inside that import (a circular-import traceback, exit 1). A command that defers
    # signals or checks for termination has imported `common` already.
    common = sys.modules.get("emos.tools.cli.common")
    if common is not None and hasattr(common, "hold_signal"):
        common.note_termination(signum)
        if common.hold_signal(signum):
            return  # inside signals_deferred(): delivered as the block ends
    raise SystemExit(128 + signum)


def main(argv: list[str] | None = None) -> int:
    """Run one command; Ctrl-C (130), a closed output pipe (141) and SIGTERM (143) end it quietly."""
    from emos.transport.context import RuntimeDirError

    try:
        return _main(argv)
    except RuntimeDirError as exc:
        # The message says what is wrong and the way out; a traceback around it only hides it.
        print(f"emos: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:
        # The reader of our output went away (`emos topic echo ... | head`). Point stdout at
        # /dev/null so the interpreter's final flush does not complain a second time.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
        return 141


def _main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    # Resolve the chosen plug-in first, then let it add its own arguments and parse again.
    words = _chosen_path(argv)
    table = {"bench": BENCHMARKS, "serve": SERVICES}.get(words[0]) if words else None
    key = words[1] if table is not None and len(words) > 1 else (words[0] if words else None)
    entry = (table or COMMANDS).get(key) if key else None
    if entry is None:
        parser.parse_args(argv)  # prints usage or help and exits
        return 2
    if entry[0] != COMMANDS["run"][0]:  # `emos run` hands signals to the supervisor instead
        signal.signal(signal.SIGTERM, _terminated)
    module = importlib.import_module(entry[0])
    # Rebuild a parser whose chosen leaf gets the plug-in's arguments.
    leaf = argparse.ArgumentParser(prog="emos " + " ".join(words[:2] if table else words[:1]), description=entry[1])
    module.add_arguments(leaf)
    example = EXAMPLES.get(" ".join(words[:2] if table else words[:1]))
    if example and not leaf.epilog:
        leaf.formatter_class = argparse.RawDescriptionHelpFormatter
        leaf.epilog = "examples:\n  " + example.replace("\n", "\n  ")
    rest = argv[2 if table is not None else 1 :]
    args = leaf.parse_intermixed_args(rest) if table is None and _intermixable(leaf, entry[0]) else leaf.parse_args(rest)
    return int(module.run(args) or 0)


def _intermixable(parser: argparse.ArgumentParser, module: str) -> bool:
    """Whether options may also go between the words of a positional that takes several
    (``emos record /scan --run X /odom``). Verb groups (subparsers) get their options on every
    verb instead (emos.tools.cli.common.options_anywhere); ``emos run`` hands the words after
    its recipe to the recipe, and argparse cannot intermix REMAINDER arguments."""
    if module == COMMANDS["run"][0]:
        return False
    return not any(isinstance(a, argparse._SubParsersAction) or a.nargs in (argparse.REMAINDER, argparse.PARSER)
                   for a in parser._actions)


if __name__ == "__main__":
    sys.exit(main())
