"""``emos bench llm``: the local language model (SmolLM2-135M-Instruct through llama.cpp).

* Speed, in one run with both loaded: tokens per second and first-token latency of the same
  prompts streamed (a) in-process, through the client the LLM component uses with
  ``enable_local_model=True``, and (b) through ``emos serve models --local-llm`` over the
  OpenAI and Ollama endpoints. Same thread count on both sides (``--threads``, default: the components' own, 1); the
  prompts alternate between the paths so machine load hits both alike.
* ``fallback_to_local()`` swap: a recipe's LLM component asks a model server, whose process
  is then SIGKILLed while questions keep arriving (every ``--ask-every`` s, as a conversation or
  a timed trigger would send them); the component's ``on_component_fail`` ladder holds
  ``fallback_to_local``, so the model is loaded and warmed at activation (in the background).
  Measured: server death -> the component reports COMPONENT_FAILURE -> first answer from the
  local model; then the way back: a new server, ``change_model_client("primary")``, its answer. The
  standby variant (``enable_local_model=True`` with the server as primary: the local model is
  loaded at start and the request-level failover re-sends the question being answered) is timed
  from the kill of a server to the answer of a question asked at that moment.
"""
from __future__ import annotations

import argparse
import json
import os
import time
from typing import Any

import numpy as np

from emos.actors.agents.server.llama_backend import default_threads

PROMPTS = [
    "Name three rooms in a house.",
    "What is a robot? Answer in one sentence.",
    "Give me two tips for keeping a kitchen clean.",
    "Why do we need sleep?",
    "Describe a chair in one sentence.",
    "What is the capital of France?",
]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="print the result as JSON only")
    parser.add_argument("--threads", type=int, default=default_threads(), help=f"llama.cpp threads on both paths (default {default_threads()}, the components' default)")
    parser.add_argument("--rounds", type=int, default=3, help="passes over the prompts per path (default 3)")
    parser.add_argument("--max-tokens", type=int, default=48, help="tokens generated per prompt (default 48)")
    parser.add_argument("--swaps", type=int, default=5, help="server kills timed per fallback variant (default 5)")
    parser.add_argument("--ask-every", type=float, default=0.25, help="seconds between questions during a swap")
    parser.add_argument("--skip-swap", action="store_true", help="measure the speed only")
    parser.add_argument("--skip-speed", action="store_true", help="measure the swaps only")


def _stats(values: list[float], scale: float = 1.0) -> dict[str, float]:
    arr = np.asarray(values, dtype=float) * scale
    return {"p50": round(float(np.percentile(arr, 50)), 3), "p95": round(float(np.percentile(arr, 95)), 3),
            "max": round(float(arr.max()), 3), "mean": round(float(arr.mean()), 3), "n": len(values)}


def _stream_once(client: Any, prompt: str, max_tokens: int) -> tuple[float, float, int]:
    """(first-token latency s, decode tokens/s after the first, tokens) of one streamed answer."""
    from emos.actors.agents.types import ChatMessage, ChatRequest

    request = ChatRequest(messages=[ChatMessage(role="user", content=prompt)], stream=True, temperature=0.0,
                          max_tokens=max_tokens, options={"seed": 0})
    start = time.perf_counter()
    first = None
    tokens = 0
    last = start
    for chunk in client.chat_stream(request):
        if chunk.content:
            tokens += 1
            last = time.perf_counter()
            if first is None:
                first = last
    if first is None:
        raise RuntimeError(f"the model streamed no text for {prompt!r}")
    rate = (tokens - 1) / (last - first) if tokens > 1 and last > first else float("nan")
    return first - start, rate, tokens


def bench_speed(threads: int, rounds: int, max_tokens: int) -> dict[str, Any]:
    from emos.actors.agents.clients import GenericHTTPClient, OllamaClient
    from emos.actors.agents.models import GenericLLM, OllamaModel
    from emos.actors.agents.server.local_client import LocalLLM, LocalLLMClient

    from .agents_system import ModelServer

    server = ModelServer("--local-llm", "--threads", str(threads))
    try:
        local = LocalLLMClient(LocalLLM(n_threads=threads))
        local.initialize()
        paths = {
            "in_component": local,
            "server_openai": GenericHTTPClient(GenericLLM(name="s", checkpoint="smollm2"), port=server.port,
                                               inference_timeout=120),
            "server_ollama": OllamaClient(OllamaModel(name="o", checkpoint="smollm2"), port=server.port,
                                          inference_timeout=120),
        }
        for client in paths.values():  # warm-up: the server loads nothing lazily, but caches do
            _stream_once(client, "Hello.", 8)
        samples: dict[str, dict[str, list[float]]] = {k: {"first": [], "rate": [], "tokens": []} for k in paths}
        for _ in range(rounds):
            for prompt in PROMPTS:
                for name, client in paths.items():
                    first, rate, tokens = _stream_once(client, prompt, max_tokens)
                    samples[name]["first"].append(first)
                    if rate == rate:  # not NaN
                        samples[name]["rate"].append(rate)
                    samples[name]["tokens"].append(tokens)
        for client in paths.values():
            client.deinitialize() if client is local else client.close()
        return {name: {"first_token_ms": _stats(s["first"], 1000.0), "tokens_per_s": _stats(s["rate"]),
                       "tokens_per_answer": round(float(np.mean(s["tokens"])), 1)}
                for name, s in samples.items()}
    finally:
        server.stop()


SWAP_RECIPE = """
from emos import Launcher, Topic
from emos.events.action import Action
from emos.actors.agents import LLM, LLMConfig, OllamaClient, OllamaModel
q = Topic(name="local_q", msg_type="String")
a = Topic(name="local_a", msg_type="String")
llm = LLM(inputs=[q], outputs=[a], trigger=q, component_name="local_llm",
          model_client=OllamaClient(OllamaModel(name="server", checkpoint="emos-scripted"), port={port}),
          config=LLMConfig(max_new_tokens=16, temperature=0.0, ncpu_local_model={threads}, enable_local_model={standby}))
llm.on_component_fail(action=Action(llm.fallback_to_local), max_retries=3)
launcher = Launcher(multi_processing=True)
launcher.add_pkg(components=[llm])
launcher.bringup()
"""


def swap_recipe(port: int, standby: bool, threads: int = 1) -> str:
    return SWAP_RECIPE.format(port=port, standby=standby, threads=threads)


def _answer_after(sub: Any, pub: Any, start: float, ask_every: float, timeout: float = 60.0,
                  status: Any = None) -> tuple[str, float, float | None]:
    """Ask every ``ask_every`` s until a reply that is not the scripted server's arrives:
    (the reply, when it arrived, when ``status`` first said COMPONENT_FAILURE or None)."""
    from emos.msgs import String
    from emos.msgs.status import ComponentStatus

    end = start + timeout
    next_ask = start
    n = 0
    failed_at = None
    while time.perf_counter() < end:
        now = time.perf_counter()
        if ask_every > 0 and now >= next_ask:
            pub.publish(String(data=f"What is a kitchen? ({n})"))
            n += 1
            next_ask = now + ask_every
        if status is not None and failed_at is None and any(
                m.status == ComponentStatus.STATUS_FAILURE_COMPONENT_LEVEL for m in status.take()):
            failed_at = time.perf_counter()
        for msg in sub.take():
            if not msg.data.startswith("You said:"):  # the scripted server's answers all do
                return msg.data, time.perf_counter(), failed_at
        time.sleep(0.001)
    raise TimeoutError("no answer from the local model after the server died")


def _wait_for(sub: Any, text: str, timeout: float) -> float:
    """Wait for the reply ``text`` (replies to older questions are skipped); when it came."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if any(m.data == text for m in sub.take()):
            return time.perf_counter()
        time.sleep(0.001)
    raise TimeoutError(f"no reply {text!r} within {timeout:.0f} s")


def _wait_standby(recipe: Any, timeout: float = 180.0) -> dict[str, Any]:
    """The component's local_model_state() once its standby model is loaded and warmed."""
    end = time.monotonic() + timeout
    while True:
        state = recipe.call_method("local_llm", "local_model_state")
        if state.get("error"):
            raise RuntimeError(f"the standby local model failed to load: {state['error']}")
        if state.get("loaded") and state.get("warm_s") is not None:
            return dict(state)
        if time.monotonic() > end:
            raise TimeoutError(f"the standby local model was not loaded after {timeout:.0f} s: {state}")
        time.sleep(0.1)


def bench_swap(swaps: int, ask_every: float, standby: bool, threads: int = 1) -> dict[str, Any]:
    """Kill the model server ``swaps`` times. Per kill: server death -> the component reports
    COMPONENT_FAILURE (``detect``), -> the local model's first answer (``swap``); then a new
    server on the same port, ``change_model_client("primary")``, and the time until the server
    answers again (``back``: the way back after a fallback)."""
    from emos.msgs import String
    from emos.msgs.status import ComponentStatus

    from .agents_system import ModelServer, RunningRecipe, _server_on

    server = ModelServer()
    port = server.port
    recipe = None
    swap_s, detect_s, back_s, answers = [], [], [], []
    try:
        recipe = RunningRecipe(swap_recipe(port, standby, threads), ["local_llm"])
        pub, sub = recipe.publisher("/local_q", String), recipe.subscriber("/local_a", String)
        status = recipe.subscriber("/local_llm/status", ComponentStatus)
        loaded = _wait_standby(recipe)  # loaded at activation, in the background: wait for it once
        for i in range(swaps):
            if i:  # a fresh server on the same port, and the component back on it
                server = _server_on(port)
                asked = time.perf_counter()
                if not recipe.call_method("local_llm", "change_model_client", "primary"):
                    raise RuntimeError("change_model_client('primary') refused")
                pub.publish(String(data=f"warm {i}"))
                back_s.append(_wait_for(sub, f"You said: warm {i}", 120.0) - asked)
            else:
                pub.publish(String(data=f"warm {i}"))
                _wait_for(sub, f"You said: warm {i}", 120.0)
            time.sleep(0.3)
            status.take()  # statuses from before the kill
            server.kill()
            start = time.perf_counter()
            if standby:
                pub.publish(String(data="What is a kitchen?"))
            text, end, failed = _answer_after(sub, pub, start, 0.0 if standby else ask_every, status=status)
            swap_s.append(end - start)
            if failed is not None:
                detect_s.append(failed - start)
            answers.append(text)
            time.sleep(0.5)
            sub.take()  # answers to questions still queued
        return {"swap_ms": _stats(swap_s, 1000.0), "detect_ms": _stats(detect_s, 1000.0) if detect_s else None,
                "back_to_primary_ms": _stats(back_s, 1000.0) if back_s else None,
                "standby_load_s": loaded.get("load_s"), "standby_warm_s": loaded.get("warm_s"),
                "answers": answers, "swaps_ms": [round(t * 1000.0, 1) for t in swap_s]}
    finally:
        if recipe is not None:
            recipe.stop()
        server.kill()


def run(args: argparse.Namespace) -> int:
    os.environ.setdefault("HF_HUB_OFFLINE", "1")
    if args.threads < 1 or args.rounds < 1 or args.max_tokens < 2 or args.swaps < 1 or args.ask_every <= 0:
        raise SystemExit("--threads, --rounds, --swaps must be positive, --max-tokens >= 2, --ask-every > 0")
    from emos.actors.agents.server.gguf import packaged_smollm2, require_llama_cpp

    try:
        require_llama_cpp()
        model = packaged_smollm2()
    except ImportError as exc:
        raise SystemExit(f"emos bench llm: {exc}") from None
    load_before = round(os.getloadavg()[0], 2)
    speed = None if args.skip_speed else bench_speed(args.threads, args.rounds, args.max_tokens)
    swap = standby = None
    if not args.skip_swap:
        swap = bench_swap(args.swaps, args.ask_every, standby=False, threads=args.threads)
        standby = bench_swap(args.swaps, args.ask_every, standby=True, threads=args.threads)
    result = {"model": model.name, "threads": args.threads, "cpus": os.cpu_count(), "load_1min": load_before,
              "load_1min_after": round(os.getloadavg()[0], 2), "omp_wait_policy": os.environ.get("OMP_WAIT_POLICY"),
              "speed": speed, "fallback_to_local": swap, "standby_failover": standby}
    if args.json:
        print(json.dumps(result))
        return 0
    print(f"model {model.name}, {args.threads} llama.cpp threads, {os.cpu_count()} CPUs, "
          f"load {result['load_1min']} -> {result['load_1min_after']}")
    if speed is not None:
        print(f"{'path':<16} {'first token p50/p95 ms':>24} {'tokens/s p50 (mean)':>22} {'tokens/answer':>14}")
        for name, s in speed.items():
            ft, tr = s["first_token_ms"], s["tokens_per_s"]
            print(f"{name:<16} {ft['p50']:>11.1f} / {ft['p95']:<10.1f} {tr['p50']:>12.1f} ({tr['mean']:.1f})    {s['tokens_per_answer']:>10}")
    for label, r in (("fallback_to_local() ladder", swap), ("standby failover (enable_local_model)", standby)):
        if r is not None:
            sw, det, back = r["swap_ms"], r["detect_ms"], r["back_to_primary_ms"]
            print(f"{label}: server death -> local answer p50 {sw['p50']:.0f} ms, p95 {sw['p95']:.0f} ms, "
                  f"max {sw['max']:.0f} ms ({sw['n']} kills; goal p95 <= 2000 ms)")
            if det is not None:
                print(f"    death -> COMPONENT_FAILURE reported p50 {det['p50']:.0f} ms; standby loaded in "
                      f"{r['standby_load_s']:.2f} s, warmed in {r['standby_warm_s']:.2f} s (at activation)")
            if back is not None:
                print(f"    change_model_client('primary') -> the restarted server's answer p50 {back['p50']:.0f} ms, "
                      f"max {back['max']:.0f} ms")
    return 0
