"""The ``emos`` command line.

Subcommands live in their own modules and are loaded lazily, so ``emos status`` never pays for
importing pybullet or torch. Each plug-in module exposes ``add_arguments(parser)`` and
``run(args) -> int`` (the exit code).
"""
from __future__ import annotations

import argparse
import importlib
import sys

# name -> (module, one-line help). Modules are imported only when their command runs.
COMMANDS: dict[str, tuple[str, str]] = {
    "run": ("emos.supervisor.cli_run", "run a recipe script under the supervisor"),
    "status": ("emos.supervisor.cli_status", "show the live supervision tree of a running system"),
    "topic": ("emos.supervisor.cli_topic", "list, echo, measure or publish topics"),
}

# `emos bench NAME`: one module per benchmark, owned by the part it measures.
BENCHMARKS: dict[str, tuple[str, str]] = {
    "ipc": ("emos.supervisor.bench.ipc", "shared-memory topic latency and throughput vs multiprocessing"),
    "restart": ("emos.supervisor.bench.restart", "kill-to-detect and kill-to-recover times of the supervisor"),
    "nav": ("emos.actors.nav.bench", "navigation algorithm kernels: costs, mapping, safety, DWA, planners"),
    "navloop": ("emos.actors.nav.bench_navloop", "scan to motor command through LocalMapper, Controller and DriveManager processes"),
    "sim": ("emos.actors.sim.bench", "simulation speed relative to real time"),
    "barn": ("emos.actors.sim.barn", "BARN navigation benchmark"),
    "agents": ("emos.actors.agents.bench", "semantic routing and vector-store query times"),
}

# `emos serve NAME`: long-running development services.
SERVICES: dict[str, tuple[str, str]] = {
    "models": ("emos.actors.agents.server.cli", "local OpenAI- and Ollama-compatible model server"),
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


def main(argv: list[str] | None = None) -> int:
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
    module = importlib.import_module(entry[0])
    # Rebuild a parser whose chosen leaf gets the plug-in's arguments.
    leaf = argparse.ArgumentParser(prog="emos " + " ".join(words[:2] if table else words[:1]), description=entry[1])
    module.add_arguments(leaf)
    args = leaf.parse_args(argv[2 if table is not None else 1 :])
    return int(module.run(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
