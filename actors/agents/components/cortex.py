"""``Cortex``: a language model that plans a task with every action the running system offers,
runs the plan, watches each step, and replans when a step fails (EmbodiedAgents' Cortex).

    cortex = Cortex(inputs=[task_topic], model_client=client, component_name="cortex",
                    config=CortexConfig(places={"kitchen": (2.0, 6.0)}))

A task arrives as text on an input topic, or as a goal of the ``<component>/run_task`` action
(whose feedback is every plan, step and outcome, and whose result is the report). At each task
the component asks the run what it offers (:mod:`..logic.cortex_tools`: action servers,
services, the Planner's navigation goals, a Vision's snapshot, a TextToSpeech's voice, and the
recipe's own ``add_tool``), plans with the model (:mod:`..logic.cortex_plan`) and runs each
step as an ``emos.actions`` Action through :func:`emos.events.runner.run_action`, the function
the Monitor runs events' actions with; only the runtime is its own (:class:`CortexRuntime`: it
waits for an action server's result, which an event does not). After each step the target
component's state is read from its control socket: a component that crashed or reports
COMPONENT_FAILURE fails the step.

Outputs: ``/<component>/plan`` (each plan the model made), ``/<component>/steps`` (each step
as it starts), ``/<component>/outcome`` (each step's outcome, refusals, replans and the task's
end), all ``String`` (JSON), shown by the web UI like any String topic; plus any String outputs
the recipe gives, which get the model's final summary.
"""
from __future__ import annotations

import asyncio
import collections
import functools
import json
import logging
import threading
import time
import uuid
from collections.abc import Callable, Mapping
from typing import Any, ClassVar

from attrs import define, field

from emos.config import validators as V
from emos.core import control as C
from emos.core.discovery import component_workers
from emos.core.rpc import RpcConnectionError
from emos.events.runner import ActionRuntime, run_action
from emos.io.fixed import FixedInput
from emos.io.topic import Topic
from emos.msgs import std as D

from ..errors import ModelClientError
from ..logic.cortex_plan import CortexPlanner, PlanEvent, PlanningError, StepOutcome, TaskReport
from ..logic.cortex_tools import CortexTool, tools_from_info
from ..logic.cortex_watch import (
    Observation,
    RecoveryBudget,
    from_event_outcome,
    from_status,
    from_supervisor_event,
    level_name,
    recovery_task,
)
from ..logic.tools import tool_spec_from_description
from ..types import ToolSpec
from .base import ModelComponent, ModelComponentConfig
from .convert import TEXTUAL_TYPES, text_of
from .cortex_interfaces import CortexTaskFeedback, CortexTaskGoal, CortexTaskResult


def _places(instance: Any, attribute: Any, value: Any) -> None:
    if not isinstance(value, Mapping):
        raise TypeError(f"CortexConfig.places: expected a mapping of place names to (x, y), got {type(value).__name__}")
    for name, xy in value.items():
        ok = isinstance(name, str) and name and isinstance(xy, (list, tuple)) and len(xy) == 2 and \
            all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in xy)
        if not ok:
            raise ValueError(f"CortexConfig.places: {name!r}: expected a name and (x, y) in metres, got {xy!r}")


@define(kw_only=True)
class CortexConfig(ModelComponentConfig):
    """Cortex options."""

    max_replans: int = field(default=3, validator=V.in_range(0, 100))
    """Revised plans per task after failed steps before the task is given up."""
    max_refusals: int = field(default=3, validator=V.in_range(0, 100))
    """Refused answers per task (malformed, unknown tool, wrong arguments) before it is given up."""
    max_steps: int = field(default=20, validator=V.in_range(1, 1000))
    step_timeout: float = field(default=300.0, validator=V.in_range(0.1, 86_400.0))
    """Seconds one step (a navigation goal: the whole drive) may take before it counts as failed."""
    discovery_timeout: float = field(default=5.0, validator=V.in_range(0.1, 600.0))
    temperature: float = field(default=0.0, validator=V.in_range(0.0, 2.0))
    max_new_tokens: int = field(default=300, validator=V.in_range(1, 100_000))
    system_prompt: str | None = field(default=None)
    places: dict = field(factory=dict, validator=_places)
    """Named map positions, offered to the model as ``navigate_to(place)``."""
    discover: bool = field(default=True)
    """Offer what the run's components serve; False: only the tools the recipe adds."""
    exclude_components: list = field(factory=list)
    monitor_period: float = field(default=0.5, validator=V.in_range(0.05, 60.0))
    """As the launcher's monitor: seconds between two looks at the run's health and events."""
    max_recoveries: int = field(default=3, validator=V.in_range(0, 100))
    """As the launcher's monitor: recovery tasks per component within ``recovery_window`` (0: observe only)."""
    recovery_window: float = field(default=60.0, validator=V.in_range(1.0, 86_400.0))


class CortexRuntime(ActionRuntime):
    """How Cortex's steps reach the system: the component's own event loop and control clients.
    Unlike an event's, a goal sent here is waited for: its result is the step's outcome."""

    def __init__(self, cortex: Cortex) -> None:
        self.cortex = cortex
        node = cortex.node
        self.ctx = node.ctx
        self.log = cortex.get_logger()
        self.timeout = cortex.config.step_timeout
        self.links = C.AsyncControlClient(self.ctx, queue_timeout=2.0)
        self._subs: dict[str, Any] = {}
        self._pubs: dict[str, Any] = {}
        self._lock = threading.Lock()

    async def call_component(self, component: str, op: str, timeout: float, **payload: Any) -> Any:
        return await self.links.call(component, op, timeout, **payload)

    async def lifecycle(self, component: str, op: str, wait_time: float = 0.0) -> Any:
        from emos.core.rpc import AsyncRpcClient

        sock = self.cortex.node.supervisor_socket
        if not sock:
            raise RuntimeError("no supervisor to send the lifecycle request to")
        client = AsyncRpcClient(sock)
        try:
            return await client.call(C.SUPERVISOR_LIFECYCLE, component=component, request=op, wait_time=wait_time, by="cortex",
                                     timeout=self.timeout + wait_time)
        finally:
            await client.close()

    async def send_goal(self, name: str, types: tuple[Any, Any, Any], goal: Any, component: str | None = None) -> Any:
        from emos.core.services import ActionClient

        client = ActionClient(name, *types, ctx=self.ctx)
        goal_id = uuid.uuid4().hex
        try:
            return await self.run_function(client.send_goal, (goal,), {"timeout": self.timeout, "goal_id": goal_id}, self.timeout)
        except TimeoutError:
            # A step that ran out of time must not keep the robot driving: cancel it on the server.
            try:
                await self.run_function(client.cancel, (goal_id,), {}, 10.0)
                outcome = "the goal was cancelled"
            except Exception as exc:
                self.log.warning("[%s] cancelling goal %s of %s after its step timed out: %s", self.cortex.component_name, goal_id, name, exc)
                outcome = f"cancelling the goal failed ({exc})"
            raise TimeoutError(f"action {name}: no result within step_timeout={self.timeout:g} s; {outcome}") from None

    def publish(self, topic: Topic, msg: Any) -> None:
        from emos.transport.select import open_publisher

        with self._lock:
            pub = self._pubs.get(topic.name)
            if pub is None:
                pub = self._pubs[topic.name] = open_publisher(self.ctx, topic, publisher_id=self.cortex.component_name)
        pub.publish(msg)

    def watch(self, topic: Topic) -> None:
        """Subscribe now, so that the latest message is there when a step asks for it."""
        from emos.transport.select import open_subscriber

        with self._lock:
            if topic.name not in self._subs:
                self._subs[topic.name] = open_subscriber(self.ctx, topic, queue_size=2)

    def latest(self, topic: str) -> Any | None:
        sub = self._subs.get(topic)
        return sub.latest() if sub is not None else None

    async def health(self, component: str) -> tuple[bool, str]:
        """Whether ``component`` is up and not in COMPONENT_FAILURE, and its state in words."""
        try:
            state = await self.links.call(component, C.GET_STATE, 5.0)
        except Exception as exc:
            return False, f"component {component!r} is not running (crashed or stopped): {exc}"
        health = str(state.get("health", "?")) if isinstance(state, dict) else "?"
        lifecycle = str(state.get("state", "?")) if isinstance(state, dict) else "?"
        if health == "COMPONENT_FAILURE" or lifecycle not in ("active", "ACTIVE"):
            return False, f"component {component!r} is {lifecycle}, health {health}"
        return True, f"{component} {health.lower()}"

    async def close(self) -> None:
        await self.links.close()
        for item in list(self._subs.values()) + list(self._pubs.values()):
            try:
                item.close()
            except Exception:
                pass
        self._subs.clear()
        self._pubs.clear()


def judge(result: Any) -> StepOutcome:
    """A step's outcome from what its action returned."""
    if result is False:
        return StepOutcome(False, "the action returned False", result)
    success = getattr(result, "success", None)
    message = str(getattr(result, "message", "") or "")
    if success is False:
        return StepOutcome(False, message or f"{type(result).__name__}.success is False", result)
    if success is True:
        return StepOutcome(True, message or "succeeded", result)
    if result is None or result is True:
        return StepOutcome(True, "done", result)
    return StepOutcome(True, str(result)[:300], result)


class Cortex(ModelComponent):
    CONFIG_CLASS: ClassVar[type] = CortexConfig
    ALLOWED_INPUTS: ClassVar[tuple[type, ...]] = TEXTUAL_TYPES
    ALLOWED_OUTPUTS: ClassVar[tuple[type, ...]] = (D.String,)

    def __init__(self, *, inputs: list[Topic] | None = None, outputs: list[Topic] | None = None, model_client: Any,
                 config: CortexConfig | None = None, trigger: Any = None, component_name: str, **kwargs: Any) -> None:
        inputs = list(inputs or [])
        answers = list(outputs or [])
        self.plan_topic = Topic(name=f"{component_name}/plan", msg_type="String")
        self.steps_topic = Topic(name=f"{component_name}/steps", msg_type="String")
        self.outcome_topic = Topic(name=f"{component_name}/outcome", msg_type="String")
        # What it observes as the launcher's monitor (add_pkg(monitor=...)): one JSON object per message.
        self.observations_topic = Topic(name=f"{component_name}/observations", msg_type="String")
        if trigger is None:
            trigger = [t for t in inputs if not isinstance(t, FixedInput)] or 1.0
        super().__init__(inputs=inputs, outputs=answers + [self.plan_topic, self.steps_topic, self.outcome_topic, self.observations_topic],
                         model_client=model_client, config=config, trigger=trigger, component_name=component_name, **kwargs)
        self.config: CortexConfig
        self._answer_topics = [t.name for t in answers]
        self._own_tools: dict[str, CortexTool] = {}
        self._runtime: CortexRuntime | None = None
        self.last_report: TaskReport | None = None
        self.last_tools: list[str] = []
        self._outcomes_topic: str | None = None
        self._monitoring = False  # set by the launcher (serve_as_monitor) before the run starts
        self._watch: _Watch | None = None
        self.observations: list[dict] = []  # the last ones (bounded), for last_observations()

    # ------------------------------------------------------------------ recipe API
    def add_tool(self, tool: Callable[..., Any], tool_description: dict | ToolSpec, component: str | None = None) -> None:
        """Offer ``tool`` (a component method: it runs in that component's process; or a function:
        it runs here) to the planner, with an OpenAI-style description of its arguments."""
        from emos.events.action import Action

        spec = tool_spec_from_description(tool_description)
        probe = Action(tool)  # classifies it now: a private method or a non-callable fails here
        owner = component or probe.component
        self._own_tools[spec.name] = CortexTool(spec, functools.partial(_own_action, tool), owner, probe.kind)

    def serve_as_monitor(self, outcomes_topic: str | None = None) -> None:
        """Called by the Launcher (``add_pkg(monitor=cortex)``) before the run starts: watch the
        run's health, the supervisor's events and the Monitor's event outcomes on
        ``outcomes_topic``, and plan a recovery when something is in trouble."""
        self._monitoring = True
        self._outcomes_topic = outcomes_topic

    def __deepcopy__(self, memo: dict) -> Cortex:
        """A restart's copy (threaded mode) reaches the system through a runtime of its own."""
        new = super().__deepcopy__(memo)
        assert isinstance(new, Cortex)
        new._runtime, new.last_report, new.last_tools, new._watch, new.observations = None, None, [], None, []
        return new

    # ------------------------------------------------------------------ lifecycle
    def custom_on_configure(self) -> None:
        super().custom_on_configure()
        self.create_action_server(f"{self.component_name}/run_task", CortexTaskGoal, CortexTaskFeedback, CortexTaskResult,
                                  self._run_task_goal)

    def custom_on_activate(self) -> Any:
        ready = super().custom_on_activate()
        if self._monitoring:
            self._watch = _Watch(self)
            self.create_timer(self.config.monitor_period, self._watch.tick)
        return ready

    def custom_on_deactivate(self) -> None:
        watch, self._watch = self._watch, None
        if watch is not None:
            watch.close()
        runtime, self._runtime = self._runtime, None
        loop = self._node.loop if self._node is not None else None
        if runtime is not None and loop is not None and loop.is_running():
            asyncio.run_coroutine_threadsafe(runtime.close(), loop)
        super().custom_on_deactivate()

    # ------------------------------------------------------------------ steps
    def missing_inputs(self, inputs: Mapping[str, Any]) -> list[str]:
        return []

    def prepare(self, inputs: dict[str, Any], trigger: Topic | None) -> Callable[[], None] | None:
        if trigger is None or trigger.name not in inputs:
            return None
        task = text_of(inputs[trigger.name]).strip()
        if not task:
            return None

        def job() -> None:
            self.run_task(task)

        return job

    def _run_task_goal(self, goal_handle: Any) -> CortexTaskResult:
        goal: CortexTaskGoal = goal_handle.goal

        def feedback(event: PlanEvent) -> None:
            goal_handle.publish_feedback(CortexTaskFeedback(kind=event.kind, text=event.text[:2000]))

        worker = self._worker
        done = threading.Event()
        box: list[TaskReport | BaseException] = []

        def job() -> None:
            try:
                box.append(self.run_task(goal.task, feedback))
            except BaseException as exc:  # noqa: BLE001 - reported in the result
                box.append(exc)
            finally:
                done.set()

        # One task at a time, on the model worker: a topic task and a goal never plan together.
        if worker is None or not worker.submit(job):
            return CortexTaskResult(success=False, message=f"{self.component_name} is not active")
        while not done.wait(0.2):
            if goal_handle.is_cancel_requested:
                return CortexTaskResult(success=False, message="cancelled (the running step ends first)")
        item = box[0]
        if isinstance(item, BaseException):
            return CortexTaskResult(success=False, message=f"{type(item).__name__}: {item}")
        return CortexTaskResult(success=item.success, answer=item.answer, message=item.reason or "task done",
                                steps=len(item.steps), replans=item.replans, report=json.dumps(item.asdict(), default=str))

    # ------------------------------------------------------------------ planning (worker thread)
    def runtime(self) -> CortexRuntime:
        if self._runtime is None:
            self._runtime = CortexRuntime(self)
        return self._runtime

    def _on_loop(self, coro: Any, timeout: float) -> Any:
        loop = self.node.loop
        if loop is None:
            raise RuntimeError(f"component {self.component_name!r} is not running")
        return asyncio.run_coroutine_threadsafe(coro, loop).result(timeout)

    def discover(self) -> dict[str, CortexTool]:
        """The tools the run offers now (see :mod:`..logic.cortex_tools`), plus the recipe's."""
        tools: dict[str, CortexTool] = {}
        if self.config.discover:
            tools.update(self._on_loop(self._discover(), self.config.discovery_timeout * 4 + 5.0))
        tools.update(self._own_tools)
        return tools

    async def _discover(self) -> dict[str, CortexTool]:
        from emos.core.rpc import AsyncRpcClient

        rt = self.runtime()
        timeout = self.config.discovery_timeout
        names: list[str] = []
        sock = self.node.supervisor_socket
        if sock:
            client = AsyncRpcClient(sock)
            try:
                tree = await client.call(C.SUPERVISOR_TREE, timeout=timeout)
                names = component_workers(tree.get("tree") if isinstance(tree, dict) else None)
            except Exception as exc:
                self._errors("discover", "[%s] the supervisor did not list the components: %s", self.component_name, exc)
            finally:
                await client.close()
        skip = {self.component_name, *map(str, self.config.exclude_components)}
        places = {str(k): (float(v[0]), float(v[1])) for k, v in self.config.places.items()}

        def topic_of(name: str, type_name: str) -> Topic:
            topic = Topic(name=name, msg_type=type_name)
            if not issubclass(topic.msg_type, D.String):
                rt.watch(topic)
            return topic

        tools: dict[str, CortexTool] = {}
        if self._monitoring:
            # The monitor's own tool: restart a component through the supervisor (counted
            # against its group's intensity, like any restart request).
            targets = [n for n in names if n not in skip]
            if targets:
                spec = ToolSpec(name=RESTART_TOOL, description="Restart a component of the run (a fresh process; its state is lost).",
                                parameters={"type": "object", "properties": {"component": {"type": "string", "enum": targets}},
                                            "required": ["component"]})
                tools[RESTART_TOOL] = CortexTool(spec, lambda args: None, None, "lifecycle")
        for name in names:
            if name in skip:
                continue
            try:
                info = await rt.links.call(name, C.INFO, timeout)
            except Exception as exc:  # one silent component must not hide the others
                self._errors(f"info:{name}", "[%s] component %r did not describe itself: %s", self.component_name, name, exc)
                continue
            if isinstance(info, dict):
                for tool in tools_from_info(info, places, topic_of):
                    tools.setdefault(tool.spec.name, tool)
        return tools

    def execute(self, tool: CortexTool, arguments: dict) -> StepOutcome:
        """Run one step through the events' machinery and judge it (worker thread)."""
        rt = self.runtime()
        if tool.kind == "lifecycle":  # restart_component: straight to the supervisor
            target = str(arguments.get("component", ""))
            try:
                self._on_loop(rt.lifecycle(target, "restart"), self.config.step_timeout + 5.0)
            except Exception as exc:
                return StepOutcome(False, f"restarting {target!r} failed: {type(exc).__name__}: {exc}")
            return StepOutcome(True, f"{target} restarted")
        try:
            action = tool.make(arguments)
        except (TypeError, ValueError, KeyError) as exc:  # the arguments do not build the goal
            return StepOutcome(False, f"tool {tool.spec.name!r}: cannot build the request from {arguments}: {exc}")
        timeout = self.config.step_timeout + 5.0
        try:
            result = self._on_loop(run_action(action, rt), timeout)
        except RpcConnectionError as exc:  # the server's socket closed under the step: its process died
            who = f"component {tool.component!r}" if tool.component else "the server"
            outcome = StepOutcome(False, f"{who} went away during the step (crashed or restarted): {exc}")
        except Exception as exc:
            outcome = StepOutcome(False, f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__)
        else:
            outcome = judge(result)
        if tool.component is not None and tool.component != self.component_name:
            ok, state = self._on_loop(rt.health(tool.component), 15.0)
            if not ok:
                detail = state if outcome.ok else f"{outcome.detail}; {state}"
                outcome = StepOutcome(False, detail, outcome.value)
        return outcome

    def run_task(self, task: str, feedback: Callable[[PlanEvent], None] | None = None) -> TaskReport:
        """Plan and run ``task`` (worker thread); returns the report (also in ``last_report``)."""
        self.get_logger().info("[%s] task: %s", self.component_name, task)
        try:
            tools = self.discover()
        except Exception as exc:
            tools = dict(self._own_tools)
            self._errors("discover", "[%s] discovery failed, planning with the recipe's tools only: %s", self.component_name, exc)

        self.last_tools = sorted(tools)

        def on_event(event: PlanEvent) -> None:
            topic = {"plan": self.plan_topic, "step": self.steps_topic}.get(event.kind, self.outcome_topic)
            self.publish_output(topic, json.dumps({"kind": event.kind, "text": event.text, **event.data}, default=str))
            log = self.get_logger().warning if event.kind in ("refused", "replan") else self.get_logger().info
            log("[%s] %s: %s", self.component_name, event.kind, event.text)
            if feedback is not None:
                feedback(event)

        def chat(request: Any) -> Any:
            return self.call_model(lambda client: client.chat(request))

        try:
            planner = CortexPlanner(chat, [t.spec for t in tools.values()], lambda name, args: self.execute(tools[name], args),
                                    max_replans=self.config.max_replans, max_refusals=self.config.max_refusals,
                                    max_steps=self.config.max_steps, temperature=self.config.temperature,
                                    max_tokens=self.config.max_new_tokens, on_event=on_event,
                                    **({"system_prompt": self.config.system_prompt} if self.config.system_prompt else {}))
            report = planner.run(task)
        except PlanningError as exc:
            report = TaskReport(task=task, reason=str(exc))
            on_event(PlanEvent("done", f"task failed: {exc}", {"success": False}))
        except ModelClientError as exc:
            report = TaskReport(task=task, reason=f"the model could not be reached: {exc}")
            on_event(PlanEvent("done", f"task failed: {report.reason}", {"success": False}))
        self.last_report = report
        if report.success:
            self.health_status.set_healthy()
            for topic in self.out_topics:
                if topic.name in self._answer_topics:
                    self.publish_output(topic, report.answer)
        else:
            self.health_status.set_fail_algorithm(algorithm_names=["planning"], message=report.reason[:300])
        return report

    def tool_names(self) -> list[str]:
        """The tools the last task was planned with (``emos component call cortex execute_method
        method=tool_names``)."""
        return list(self.last_tools)

    def monitored_components(self) -> list[str]:
        """The components it watches as the launcher's monitor (empty until its first look)."""
        return list(self._watch.components) if self._watch is not None else []

    def last_observations(self) -> list[dict]:
        """What it observed last as the launcher's monitor (``emos component call cortex
        execute_method method=last_observations``)."""
        return list(self.observations)

    def observe(self, observations: list[Observation]) -> None:
        """Loop thread: publish what was observed; start a recovery for a component in trouble
        (one at a time per component, within the budget)."""
        watch = self._watch
        for o in observations:
            record = {"at": time.time(), **o.asdict()}
            self.observations = (self.observations + [record])[-100:]
            self.publish_output(self.observations_topic, json.dumps(record))
            (self.get_logger().warning if o.trouble else self.get_logger().info)("[%s] observed: %s", self.component_name, o.text)
        if watch is None or self.config.max_recoveries == 0:
            return
        troubled: dict[str, list[Observation]] = {}
        for o in observations:
            if o.trouble and o.component and o.component != self.component_name:
                troubled.setdefault(o.component, []).append(o)
        for component, seen in troubled.items():
            if component in watch.recovering:
                continue
            if not watch.budget.allow(component, time.monotonic()):
                self._errors(f"budget:{component}", "[%s] %s is in trouble again, but its recovery budget (%d in %g s) is spent: "
                             "observing only", self.component_name, component, self.config.max_recoveries, self.config.recovery_window)
                continue
            task = recovery_task(component, watch.history(component) or seen)
            watch.recovering.add(component)

            def job(component: str = component, task: str = task) -> None:
                try:
                    report = self.run_task(task)
                    self.publish_output(self.observations_topic, json.dumps(
                        {"at": time.time(), "component": component, "kind": "recovery", "trouble": False,
                         "text": f"recovery of '{component}' {'succeeded' if report.success else 'failed'}: {report.answer or report.reason}",
                         "success": report.success, "steps": len(report.steps)}))
                finally:
                    watch.recovering.discard(component)

            worker = self._worker
            if worker is None or not worker.submit(job):
                watch.recovering.discard(component)
                self._errors(f"submit:{component}", "[%s] cannot plan the recovery of %s now (busy)", self.component_name, component)

    def last_task_report(self) -> dict:
        """The last task's report (``emos component call cortex execute_method method=last_task_report``)."""
        return self.last_report.asdict() if self.last_report is not None else {}


RESTART_TOOL = "restart_component"


class _Watch:
    """The monitor's look at the run, every ``monitor_period`` on the component's loop: the
    supervisor's event log, each component's status, the Monitor's event outcomes."""

    def __init__(self, cortex: Cortex) -> None:
        self.cortex = cortex
        self.since = time.monotonic()  # the supervisor's event stamps are CLOCK_MONOTONIC (same host)
        self.levels: dict[str, str] = {}
        self.stamps: dict[str, float] = {}
        self.components: list[str] = []
        self.status_topics: dict[str, str] = {}
        self.tree_at = 0.0
        self.recovering: set[str] = set()
        self.budget = RecoveryBudget(cortex.config.max_recoveries, cortex.config.recovery_window)
        self.recent: collections.deque[Observation] = collections.deque(maxlen=50)
        self._task: asyncio.Future[Any] | None = None
        self._client: Any = None
        self._outcomes: Any = None

    def history(self, component: str) -> list[Observation]:
        return [o for o in self.recent if o.component == component]

    def tick(self) -> None:
        if self._task is None or self._task.done():
            self._task = asyncio.ensure_future(self._look())

    async def _look(self) -> None:
        cortex = self.cortex
        try:
            observations = await self._gather()
        except Exception as exc:  # a look that fails (the supervisor restarting) is retried next tick
            cortex._errors("watch", "[%s] watching the run: %s: %s", cortex.component_name, type(exc).__name__, exc)
            return
        if observations:
            self.recent.extend(observations)
            cortex.observe(observations)

    async def _gather(self) -> list[Observation]:
        from emos.core.rpc import AsyncRpcClient
        from emos.msgs.status import ComponentStatus
        from emos.transport.select import open_subscriber

        cortex = self.cortex
        rt = cortex.runtime()
        sock = cortex.node.supervisor_socket
        out: list[Observation] = []
        if sock and self._client is None:
            self._client = AsyncRpcClient(sock)
        now = time.monotonic()
        if self._client is not None and now - self.tree_at > 2.0:
            self.tree_at = now
            tree = await self._client.call(C.SUPERVISOR_TREE, timeout=5.0)
            names = component_workers(tree.get("tree") if isinstance(tree, dict) else None)
            skip = {cortex.component_name, *map(str, cortex.config.exclude_components)}
            self.components = [n for n in names if n not in skip]
            for name in self.components:
                topic = Topic(name=f"{name}/status", msg_type=ComponentStatus)
                self.status_topics[name] = topic.name
                rt.watch(topic)
            if self._outcomes is None and cortex._outcomes_topic:
                self._outcomes = open_subscriber(rt.ctx, Topic(name=cortex._outcomes_topic, msg_type="String"), queue_size=32)
        if self._client is not None:
            events = await self._client.call(C.SUPERVISOR_EVENTS, since=self.since, timeout=5.0)
            known = set(self.components)
            for event in events if isinstance(events, list) else []:
                if isinstance(event, dict) and isinstance(event.get("t"), (int, float)):
                    self.since = max(self.since, float(event["t"]) + 1e-6)
                o = from_supervisor_event(event, cortex.component_name, known)
                if o is not None:
                    out.append(o)
        for name in self.components:
            status = rt.latest(self.status_topics.get(name, ""))
            if status is None:
                continue
            stamp = status.header.stamp.to_sec()
            if stamp <= self.stamps.get(name, 0.0):
                continue  # seen already, or an older incarnation's
            self.stamps[name] = stamp
            o = from_status(name, self.levels.get(name), status)
            self.levels[name] = level_name(status.status)
            if o is not None:
                out.append(o)
        if self._outcomes is not None:
            for msg in self._outcomes.take():
                out.extend(from_event_outcome(getattr(msg, "data", "")))
        return out

    def close(self) -> None:
        """From the lifecycle (any thread): stop looking; the client closes on the loop."""
        loop = self.cortex._node.loop if self.cortex._node is not None else None
        task, self._task = self._task, None
        client, self._client = self._client, None
        if loop is not None and loop.is_running():
            if task is not None:
                loop.call_soon_threadsafe(task.cancel)
            if client is not None:
                asyncio.run_coroutine_threadsafe(client.close(), loop)
        if self._outcomes is not None:
            try:
                self._outcomes.close()
            except Exception:
                pass
            self._outcomes = None


def _own_action(tool: Callable[..., Any], args: dict) -> Any:
    from emos.events.action import Action

    return Action(tool, kwargs=dict(args))


logging.getLogger(__name__).addHandler(logging.NullHandler())
