"""Cortex's planning loop, pure: a task in words, a language model that answers with tool calls,
an executor that runs one step and says how it went; no processes, no topics.

Each round sends the model the task, the steps done so far with their outcomes, the failure
that stopped the last plan (if any) and why the last answer was refused (if it was), with the
tools in the OpenAI ``tools`` format. The model answers with one or more tool calls (a plan:
run in order) or, when the task is complete, with text (its summary). Small models often write
their calls as JSON in the text instead of the ``tool_calls`` field (SmolLM2 does): such calls
are read from the text too.

What the loop refuses, never executing any step of the plan that holds it (every call of a
plan is checked before the first runs): a malformed call (arguments that are not a JSON
object, a response the client could not decode), an unknown tool, arguments that do not match
the tool's schema, and the exact call that just failed (a revision must change something).
A refusal names the tool and the problem, goes back to the model in the next prompt, and
counts against ``max_refusals``. A step that fails (its tool raised, the action's result says
it did not succeed, its component crashed) ends that plan: the next prompt carries the failure
and asks for a revised plan, at most ``max_replans`` times per task.
"""
from __future__ import annotations

import json
import re
import time
from collections.abc import Callable, Sequence
from typing import Any

import attrs

from emos.errors import EmosError

from ..errors import MalformedResponseError
from ..types import ChatMessage, ChatRequest, ChatResponse, ToolCall, ToolSpec
from .tools import ToolError, ToolRegistry

__all__ = ["StepOutcome", "Step", "TaskReport", "CortexPlanner", "PlanEvent", "calls_from_message", "Refusal",
           "DEFAULT_SYSTEM_PROMPT"]

DEFAULT_SYSTEM_PROMPT = (
    "You are Cortex, the planner of a mobile robot. You reach the robot only through the tools. "
    "Answer with the tool calls for the remaining steps of the task, in order. If a step failed, "
    "revise the plan: do not repeat the failed call unchanged. When the task is complete, answer "
    "DONE followed by a one-sentence summary for the user, without tool calls. If you cannot call "
    'tools natively, write each call as JSON: {"name": "<tool>", "arguments": {...}}.'
)
_JSON_OBJECT = re.compile(r"\{")
_NAME_IN_TEXT = re.compile(r'"name"\s*:\s*"([^"]{1,80})"')


class PlanningError(EmosError, RuntimeError):
    """The planner was given something it cannot work with (no tools, a bad budget)."""


@attrs.frozen
class StepOutcome:
    """How one step ended: ``ok`` and a short text for the model (and the UI)."""

    ok: bool
    detail: str = ""
    value: Any = None


@attrs.frozen
class Refusal:
    """A call (or a whole answer) the planner would not execute, and why."""

    tool: str
    problem: str

    def __str__(self) -> str:
        return f"tool {self.tool!r}: {self.problem}"


@attrs.define
class Step:
    """One executed step of a task."""

    index: int
    tool: str
    arguments: dict
    ok: bool = False
    detail: str = ""
    seconds: float = 0.0

    def line(self) -> str:
        return f"{self.index}. {self.tool} {json.dumps(self.arguments, sort_keys=True)} -> {'ok' if self.ok else 'failed'}: {self.detail}"


@attrs.define
class TaskReport:
    """What became of a task: every step, the revisions and refusals, the model's summary."""

    task: str
    success: bool = False
    answer: str = ""
    reason: str = ""
    steps: list[Step] = attrs.field(factory=list)
    replans: int = 0
    refusals: list[Refusal] = attrs.field(factory=list)
    planning_seconds: list[float] = attrs.field(factory=list)

    def asdict(self) -> dict[str, Any]:
        return {"task": self.task, "success": self.success, "answer": self.answer, "reason": self.reason,
                "steps": [attrs.asdict(s) for s in self.steps], "replans": self.replans,
                "refusals": [str(r) for r in self.refusals], "planning_seconds": list(self.planning_seconds)}


@attrs.frozen
class PlanEvent:
    """What the planner reports as it goes (published on Cortex's topics): ``kind`` is one of
    ``plan``, ``refused``, ``step``, ``outcome``, ``replan``, ``done``."""

    kind: str
    text: str
    data: dict = attrs.field(factory=dict)


def _text_calls(content: str) -> tuple[list[ToolCall], list[Refusal]]:
    """Tool calls written as JSON objects ``{"name": ..., "arguments": {...}}`` in the text."""
    calls: list[ToolCall] = []
    refused: list[Refusal] = []
    decoder = json.JSONDecoder()
    pos = 0
    while True:
        match = _JSON_OBJECT.search(content, pos)
        if match is None:
            break
        start = match.start()
        try:
            value, end = decoder.raw_decode(content, start)
        except json.JSONDecodeError as exc:
            named = _NAME_IN_TEXT.search(content, start)
            if named is not None:  # a call that breaks off (or is not JSON): malformed, named
                refused.append(Refusal(named.group(1), f"malformed tool call: its JSON does not parse ({exc.msg} at character {exc.pos - start})"))
                break
            pos = start + 1
            continue
        pos = end
        if not isinstance(value, dict) or "name" not in value:
            continue
        name = value.get("name")
        if not isinstance(name, str) or not name:
            refused.append(Refusal(str(name), "malformed tool call: 'name' must be a non-empty string"))
            continue
        arguments = value.get("arguments", value.get("parameters", {}))
        if isinstance(arguments, str):  # OpenAI-style: a JSON string inside the JSON
            try:
                arguments = json.loads(arguments) if arguments.strip() else {}
            except ValueError:
                refused.append(Refusal(name, f"malformed tool call: arguments are not a JSON object: {arguments[:80]!r}"))
                continue
        if not isinstance(arguments, dict):
            refused.append(Refusal(name, f"malformed tool call: arguments must be a JSON object, got {type(arguments).__name__}"))
            continue
        calls.append(ToolCall(id=f"text_{len(calls)}", name=name, arguments=arguments))
    return calls, refused


def calls_from_message(message: ChatMessage) -> tuple[list[ToolCall], list[Refusal]]:
    """The tool calls of an answer (native ones, else JSON ones in its text) and the malformed ones."""
    if message.tool_calls:
        return list(message.tool_calls), []
    return _text_calls(message.content or "")


_CLAIMS_DONE = re.compile(r"DONE\b(?!\s+STEPS)", re.IGNORECASE)


class CortexPlanner:
    """Plans a task with ``chat`` (a ChatRequest -> ChatResponse callable: a model client) and
    runs its steps with ``execute(tool, arguments) -> StepOutcome``. ``on_event`` sees every
    plan, refusal, step and outcome as it happens."""

    def __init__(self, chat: Callable[[ChatRequest], ChatResponse], tools: Sequence[ToolSpec],
                 execute: Callable[[str, dict], StepOutcome], *, max_replans: int = 3, max_refusals: int = 3,
                 max_steps: int = 20, system_prompt: str = DEFAULT_SYSTEM_PROMPT, temperature: float = 0.0,
                 max_tokens: int = 300, on_event: Callable[[PlanEvent], None] | None = None) -> None:
        if not tools:
            raise PlanningError("Cortex has no tools to plan with: no component offers an action, service or tool")
        for what, value in (("max_replans", max_replans), ("max_refusals", max_refusals), ("max_steps", max_steps)):
            if isinstance(value, bool) or not isinstance(value, int) or value < (1 if what == "max_steps" else 0):
                raise PlanningError(f"CortexPlanner: {what} must be an int >= {1 if what == 'max_steps' else 0}, got {value!r}")
        self.chat, self.execute = chat, execute
        self.registry = ToolRegistry()
        for spec in tools:
            # The registry checks arguments against each schema; the callable is never used here.
            self.registry.register_tool(_never_called, spec)
        self.tools = self.registry.specs
        self.max_replans, self.max_refusals, self.max_steps = max_replans, max_refusals, max_steps
        self.system_prompt, self.temperature, self.max_tokens = system_prompt, temperature, max_tokens
        self.on_event = on_event or (lambda event: None)

    # ------------------------------------------------------------------ prompt
    def prompt(self, task: str, steps: list[Step], failure: Step | None, refused: list[Refusal]) -> str:
        lines = [f"TASK: {task}", "DONE STEPS:" + ("" if steps else " none")]
        lines += [s.line() for s in steps if s.ok]
        if failure is not None:
            lines.append(f"FAILED STEP: {failure.line()}")
            lines.append("Revise the plan from here: do not repeat the failed call unchanged.")
        if refused:
            lines.append("REFUSED: " + "; ".join(str(r) for r in refused) + ". Nothing of that answer was executed; answer again with valid tool calls.")
        lines.append("Call the tools for the remaining steps, or answer DONE with a summary if the task is complete.")
        return "\n".join(lines)

    def request(self, task: str, steps: list[Step], failure: Step | None, refused: list[Refusal]) -> ChatRequest:
        messages = [ChatMessage(role="system", content=self.system_prompt),
                    ChatMessage(role="user", content=self.prompt(task, steps, failure, refused))]
        return ChatRequest(messages=messages, tools=self.tools, temperature=self.temperature, max_tokens=self.max_tokens)

    # ------------------------------------------------------------------ checks
    def check(self, calls: list[ToolCall], last_failure: Step | None) -> list[Refusal]:
        """Why calls of a plan cannot run (empty: all may run)."""
        refused: list[Refusal] = []
        for call in calls:
            try:
                self.registry.validate(call)
            except ToolError as exc:
                if call.name not in self.registry:
                    refused.append(Refusal(call.name, f"unknown tool; the tools are {', '.join(sorted(s.name for s in self.tools))}"))
                else:
                    refused.append(Refusal(call.name, _schema_problem(str(exc), call.name)))
                continue
            if last_failure is not None and call.name == last_failure.tool and call.arguments == last_failure.arguments:
                refused.append(Refusal(call.name, f"repeats the call that just failed ({last_failure.detail}) unchanged; revise the plan"))
        return refused

    # ------------------------------------------------------------------ the loop
    def run(self, task: str) -> TaskReport:
        if not isinstance(task, str) or not task.strip():
            raise PlanningError(f"Cortex: a task must be a non-empty text, got {task!r}")
        report = TaskReport(task=task)
        failure: Step | None = None
        refused: list[Refusal] = []
        while True:
            started = time.perf_counter()
            try:
                response = self.chat(self.request(task, report.steps, failure, refused))
                calls, malformed = calls_from_message(response.message)
            except MalformedResponseError as exc:  # the client could not decode the model's tool call
                response, calls, malformed = None, [], [Refusal(_named(exc), f"malformed tool call: {exc.expected}, got {exc.got[:120]!r}")]
            report.planning_seconds.append(time.perf_counter() - started)
            refused = malformed + self.check(calls, failure)
            if refused:
                report.refusals += refused
                for r in refused:
                    self.on_event(PlanEvent("refused", str(r), {"tool": r.tool, "problem": r.problem}))
                if len(report.refusals) > self.max_refusals:
                    report.reason = f"gave up after {len(report.refusals)} refused answers (max_refusals={self.max_refusals}); last: {refused[-1]}"
                    break
                continue
            if not calls:
                text = (response.message.content if response is not None else "") or ""
                if failure is not None:
                    # The model stopped after a failure without revising: the task did not succeed.
                    report.reason = f"the model gave up after a failed step: {failure.line()}"
                    report.answer = text.strip()
                    break
                # "DONE" claims the task; a model echoing the prompt's own "DONE STEPS:" header
                # (SmolLM2 does) claims nothing.
                if not report.steps and (report.refusals or not _CLAIMS_DONE.match(text.strip())):
                    why = f" after {len(report.refusals)} refused answer(s)" if report.refusals else ""
                    report.reason = f"the model answered without a tool call{why}: {text.strip()[:200]!r}"
                    report.answer = text.strip()
                    break
                report.success, report.answer = True, _summary(text)
                self.on_event(PlanEvent("done", report.answer, {"steps": len(report.steps), "replans": report.replans}))
                break
            self.on_event(PlanEvent("plan", "; ".join(f"{c.name} {json.dumps(c.arguments, sort_keys=True)}" for c in calls),
                                    {"calls": [{"name": c.name, "arguments": c.arguments} for c in calls]}))
            failure = None
            for call in calls:
                if len(report.steps) >= self.max_steps:
                    report.reason = f"stopped at max_steps={self.max_steps}"
                    self.on_event(PlanEvent("outcome", report.reason, {"ok": False}))
                    return report
                step = Step(index=len(report.steps) + 1, tool=call.name, arguments=dict(call.arguments))
                self.on_event(PlanEvent("step", f"{step.index}. {step.tool} {json.dumps(step.arguments, sort_keys=True)}",
                                        {"index": step.index, "tool": step.tool, "arguments": step.arguments}))
                t0 = time.perf_counter()
                try:
                    outcome = self.execute(call.name, dict(call.arguments))
                except Exception as exc:  # an executor bug must not take the planner down: a failed step
                    outcome = StepOutcome(False, f"{type(exc).__name__}: {exc}")
                step.ok, step.detail, step.seconds = bool(outcome.ok), outcome.detail[:300], time.perf_counter() - t0
                report.steps.append(step)
                self.on_event(PlanEvent("outcome", step.line(), {"index": step.index, "ok": step.ok, "detail": step.detail}))
                if not step.ok:
                    failure = step
                    break
            if failure is not None:
                report.replans += 1
                if report.replans > self.max_replans:
                    report.reason = f"gave up after {self.max_replans} revised plans; last failure: {failure.line()}"
                    break
                self.on_event(PlanEvent("replan", f"revising the plan after: {failure.line()}", {"replans": report.replans}))
        if not report.success:
            self.on_event(PlanEvent("done", f"task failed: {report.reason}", {"success": False}))
        return report


def _never_called(**_: Any) -> None:  # pragma: no cover - the executor runs the tools
    raise AssertionError("CortexPlanner runs tools through its executor")


def _schema_problem(message: str, tool: str) -> str:
    prefix = f"arguments of tool {tool!r} do not match its schema: "
    return "wrong arguments: " + (message[len(prefix):] if message.startswith(prefix) else message)


def _named(exc: MalformedResponseError) -> str:
    match = _NAME_IN_TEXT.search(str(exc.got))
    return match.group(1) if match else "(unnamed)"


def _summary(text: str) -> str:
    text = text.strip()
    return re.sub(r"^DONE[\s:.!-]*", "", text, flags=re.IGNORECASE).strip() or "done"
