"""Actions across the bridge, both ways, for the action types both sides have.

An action type is shared when EMOS registers its parts as ``pkg/msg/X_Goal``, ``pkg/msg/X_Feedback``
and ``pkg/msg/X_Result`` (``test_msgs/msg/Fibonacci_Goal``, ... in :mod:`emos.msgs.srv`) and rclpy
can import ``pkg.action.X``. rclpy's own action machinery (``rclpy.action.ActionServer`` and
``ActionClient``) speaks the ROS 2 side; the EMOS side is :mod:`emos.core.services`.

* An EMOS component's action server (a socket under ``<run>/srv``; its types come from the
  component's ``info`` answer, as for ``emos action send_goal``) is offered on the ROS 2 graph
  under its name, as ``pkg/action/X``. A ROS 2 client's goal runs as an EMOS goal of the same id;
  its feedback, result and cancel go through. The goal runs in a thread of its own, not in one
  of rclpy's executor threads, so that long goals do not starve the topics and services; rclpy's
  ``execute`` is called when the EMOS goal has ended, to hand over the result (the ROS 2 side
  sees the goal ACCEPTED, then CANCELING if asked, until it ends).
* A ROS 2 action server (one other than this bridge) is offered to EMOS components under its
  name: an EMOS :class:`~emos.core.services.ActionClient` goal goes to the ROS 2 server.

Bad input: a goal the ROS 2 server rejects or aborts is an error for the EMOS caller naming the
action (logged once, by the EMOS action server the bridge runs); so is a ROS 2 server that goes
away mid-goal, noticed from the graph within ``GONE_AFTER_S`` (a SIGKILLed one only once DDS's
participant lease on it has run out), and one that does not answer a goal within
``ANSWER_TIMEOUT_S``. An EMOS action server that fails, refuses the goal or dies
mid-goal aborts the ROS 2 goal with the result's defaults, with one rate-limited line naming the
action. The bridge goes on.
"""
from __future__ import annotations

import importlib
import logging
import threading
import time
import uuid
from collections.abc import Callable
from typing import Any

import attrs
import numpy as np

from emos.core import control as C
from emos.errors import EmosError
from emos.interop.ros2 import env
from emos.msgs.registry import UnknownMessageType, canonical_name, registered_types, resolve
from emos.ratelimit import RateLimitedLog
from emos.transport.context import RunContext, decode_name

log = logging.getLogger("emos.ros2")
_limited = RateLimitedLog(log, interval=10.0)
ROLES = ("Goal", "Feedback", "Result")
GONE_AFTER_S = 1.0  # a ROS 2 action server missing from the graph this long has gone away
INFO_EVERY_S = 2.0  # how often components are asked which of their sockets are actions
# A goal request a ROS 2 server has not answered in this time is an error: a request sent while
# DDS is still matching a (re)started server's reply writer can be lost, and would wait forever.
ANSWER_TIMEOUT_S = 10.0


class ActionFailed(EmosError):
    """What an EMOS caller gets when the ROS 2 side refused, aborted or lost its goal."""


def emos_types_of(ros_action: str) -> tuple[type, type, type] | None:
    """EMOS (goal, feedback, result) classes of a ROS 2 action type ``pkg/action/X``, if registered."""
    package, sep, name = ros_action.partition("/action/")
    if not sep:
        return None
    types = registered_types()
    goal, feedback, result = (types.get(f"{package}/msg/{name}_{role}") for role in ROLES)
    return (goal, feedback, result) if goal is not None and feedback is not None and result is not None else None


def ros_action_of(goal: str, feedback: str, result: str) -> str | None:
    """The ROS 2 action type ``pkg/action/X`` whose parts are these EMOS type names, if they are a set."""
    package, sep, name = goal.partition("/msg/")
    if not sep or not name.endswith("_Goal"):
        return None
    base = name[: -len("_Goal")]
    if (feedback, result) != (f"{package}/msg/{base}_Feedback", f"{package}/msg/{base}_Result"):
        return None
    return f"{package}/action/{base}"


def to_ros(src: Any, cls: Any) -> Any:
    """An rclpy ``cls`` message with the fields of ``src`` (ours). rclpy's sequence setters take
    Python ints, not numpy scalars: arrays go as lists. The shared action types are flat."""
    out = cls()
    for f in attrs.fields(type(src)):
        value = getattr(src, f.name)
        setattr(out, f.name, value.tolist() if isinstance(value, np.ndarray) else value)
    return out


def to_emos(src: Any, cls: type) -> Any:
    """An instance of our ``cls`` with the fields of the rclpy message ``src`` (validated by ours)."""
    return cls(**{f.name: getattr(src, f.name) for f in attrs.fields(cls)})


def _wait(future: Any, until: Callable[[], bool] | None = None, poll: float = 0.1) -> None:
    """Block this (non-executor) thread until the rclpy ``future`` is done or ``until()`` says stop."""
    done = threading.Event()
    future.add_done_callback(lambda _f: done.set())
    while not done.wait(poll):
        if until is not None and until():
            return


@attrs.define
class _Out:
    """An EMOS action server offered to ROS 2."""

    ros_action: str
    server: Any  # rclpy ActionServer
    client: Any  # EMOS ActionClient
    running: dict[str, Any] = attrs.Factory(dict)  # EMOS goal id -> rclpy ServerGoalHandle


@attrs.define
class _In:
    """A ROS 2 action server offered to EMOS."""

    ros_action: str
    server: Any  # EMOS ActionServer
    client: Any  # rclpy ActionClient


class ActionBridge:
    """The actions part of a :class:`~emos.interop.ros2.bridge.Ros2Bridge` (same node, run and
    asyncio loop as its :class:`~emos.interop.ros2.services.ServiceBridge`)."""

    def __init__(self, ctx: RunContext, node: Any, wanted: Callable[[str], bool], skip_once: Callable[..., None], loop: Any):
        from rclpy.callback_groups import ReentrantCallbackGroup

        env.prepare_package("action_msgs")
        self.ctx, self.node, self.wanted, self._skip_once, self.loop = ctx, node, wanted, skip_once, loop
        self.group = ReentrantCallbackGroup()  # goal/cancel/result requests and replies: short, any thread
        self.to_ros: dict[str, _Out] = {}
        self.to_emos: dict[str, _In] = {}
        self._not_actions: set[str] = set()  # sockets the components list as services
        self._refused: set[str] = set()
        self._next_info = 0.0
        self._closing = threading.Event()

    # -- discovery (the forwarder thread) ------------------------------------------------------
    def discover(self, services: set[str]) -> None:
        """``services``: names the services part already bridges (not actions)."""
        known = services | set(self.to_ros) | set(self.to_emos) | self._not_actions | self._refused
        srv_dir = self.ctx.run_dir / "srv"
        candidates = set()
        if srv_dir.is_dir():
            for sock in srv_dir.glob("*.sock"):
                name = "/" + decode_name(sock.name[:-5]).lstrip("/")
                if name not in known and self.wanted(name):
                    candidates.add(name)
        if candidates and time.monotonic() >= self._next_info:
            self._next_info = time.monotonic() + INFO_EVERY_S
            for name, parts in self._emos_actions().items():
                if name in candidates:
                    self._guarded(name, self._offer_to_ros, name, parts)
        from rclpy.action.graph import get_action_names_and_types

        for name, types in get_action_names_and_types(self.node):
            if name in self.to_ros or name in self.to_emos or name in self._refused or not self.wanted(name) or len(types) != 1:
                continue
            if self._has_other_server(name):
                self._guarded(name, self._offer_to_emos, name, types[0])

    def _emos_actions(self) -> dict[str, tuple[str, str, str]]:
        """Action name -> (goal, feedback, result) type names, as the run's components describe
        what they serve; the names they list as services are remembered as not actions."""
        found: dict[str, tuple[str, str, str]] = {}
        ctl = self.ctx.run_dir / "ctl"
        for sock in sorted(ctl.glob("*.sock")) if ctl.is_dir() else []:
            try:
                info = C.call(sock, C.INFO, {}, timeout=2.0)
            except Exception as exc:  # a component starting or stopping: asked again later
                log.debug("ROS 2 bridge: component %s not described: %s", sock.name, exc)
                continue
            if not isinstance(info, dict):
                continue
            for entry in info.get("services") or []:
                if isinstance(entry, dict) and isinstance(entry.get("name"), str) and entry.get("serving"):
                    self._not_actions.add("/" + entry["name"].lstrip("/"))
            for entry in info.get("actions") or []:
                if not (isinstance(entry, dict) and isinstance(entry.get("name"), str) and entry.get("serving")):
                    continue
                names = [entry[role].get("type") if isinstance(entry.get(role), dict) else None for role in ("goal", "feedback", "result")]
                goal, feedback, result = names
                if isinstance(goal, str) and isinstance(feedback, str) and isinstance(result, str):
                    found["/" + entry["name"].lstrip("/")] = (goal, feedback, result)
        return found

    def _has_other_server(self, name: str) -> bool:
        """Whether a node other than this bridge serves action ``name`` (its status publisher)."""
        own = (self.node.get_name(), self.node.get_namespace())
        return any((p.node_name, p.node_namespace) != own for p in self.node.get_publishers_info_by_topic(f"{name}/_action/status"))

    def _guarded(self, name: str, offer: Callable[..., None], *args: Any) -> None:
        """One action that cannot be offered is left out, once, with a line naming it; the
        bridge and the other actions go on."""
        try:
            offer(*args)
        except Exception as exc:
            self._refused.add(name)
            self._skip_once(name, f"action not offered: {type(exc).__name__}: {exc}")

    def _action_class(self, name: str, ros_action: str) -> Any:
        package, _, cls_name = ros_action.partition("/action/")
        try:
            env.prepare_package(package)
            return getattr(importlib.import_module(f"{package}.action"), cls_name)
        except (ImportError, AttributeError) as exc:
            self._refused.add(name)
            self._skip_once(name, f"{ros_action} needs the ROS 2 package {package}, which rclpy cannot import ({exc})")
            return None

    # -- EMOS server, ROS 2 clients ------------------------------------------------------------
    def _offer_to_ros(self, name: str, type_names: tuple[str, str, str]) -> None:
        ros_action = ros_action_of(*type_names)
        try:
            classes: tuple[type, ...] = tuple(resolve(t) for t in type_names)
        except UnknownMessageType:
            classes = ()
        if ros_action is None or len(classes) != 3 or tuple(canonical_name(c) for c in classes) != type_names:
            self._refused.add(name)
            self._skip_once(name, f"EMOS action types {', '.join(type_names)} have no ROS 2 counterpart", logging.INFO)
            return
        action_cls = self._action_class(name, ros_action)
        if action_cls is None:
            return
        from rclpy.action import server as rclpy_server

        from emos.core.services import ActionClient, service_socket

        # rclpy's action classes are untyped.
        ActionServer: Any = rclpy_server.ActionServer
        CancelResponse: Any = rclpy_server.CancelResponse
        GoalResponse: Any = rclpy_server.GoalResponse

        client = ActionClient(name, *classes, ctx=self.ctx)
        sock = service_socket(self.ctx, name)
        route = _Out(ros_action, None, client)

        def accept(goal: Any) -> Any:
            if not sock.exists():  # the EMOS component stopped serving it
                _limited.warning(f"act:{name}", "ROS 2 bridge: action %s (%s): goal refused: the EMOS action server is not serving",
                                 name, ros_action)
                return GoalResponse.REJECT
            return GoalResponse.ACCEPT

        def cancel(handle: Any) -> Any:
            goal_id = uuid.UUID(bytes=bytes(handle.goal_id.uuid)).hex
            try:
                return CancelResponse.ACCEPT if client.cancel(goal_id) else CancelResponse.REJECT
            except Exception as exc:  # the EMOS server went away: its goal ends with it
                _limited.warning(f"act:{name}", "ROS 2 bridge: action %s: the cancel did not reach the EMOS server: %s", name, exc)
                return CancelResponse.REJECT

        def accepted(handle: Any) -> None:
            threading.Thread(target=self._run_emos_goal, args=(name, route, action_cls, handle), name=f"ros2-action{name}",
                             daemon=True).start()

        route.server = ActionServer(self.node, action_cls, name, execute_callback=lambda h: action_cls.Result(), goal_callback=accept,
                                    cancel_callback=cancel, handle_accepted_callback=accepted, callback_group=self.group)
        self.to_ros[name] = route
        log.info("ROS 2 bridge: action %s (%s) EMOS -> ROS 2", name, ros_action)

    def _run_emos_goal(self, name: str, route: _Out, action_cls: Any, handle: Any) -> None:
        """One ROS 2 goal as an EMOS goal (its own thread): then hand the end to rclpy."""
        from emos.core.services import ActionCanceled

        goal_id = uuid.UUID(bytes=bytes(handle.goal_id.uuid)).hex
        client = route.client
        route.running[goal_id] = handle
        outcome, result = "abort", None
        try:
            goal = to_emos(handle.request, client.goal_type)
            result = client.send_goal(goal, feedback_callback=lambda fb: handle.publish_feedback(to_ros(fb, action_cls.Feedback)),
                                      goal_id=goal_id)
            outcome = "succeed"
        except ActionCanceled as exc:
            outcome, result = "canceled", exc.result
        except Exception as exc:  # refused, failed, or the server died: the ROS 2 goal is aborted
            if not self._closing.is_set():
                _limited.warning(f"act:{name}", "ROS 2 bridge: action %s (%s): goal %s aborted: the EMOS action server failed: %s",
                                 name, route.ros_action, goal_id, exc)
        finally:
            route.running.pop(goal_id, None)

        def finish(h: Any) -> Any:
            # CANCELED is a legal end only after a cancel request on the ROS 2 side.
            end = outcome if outcome != "canceled" or h.is_cancel_requested else "abort"
            getattr(h, end)()
            try:
                return action_cls.Result() if result is None else to_ros(result, action_cls.Result)
            except Exception as exc:  # a result rclpy refuses: the goal still ends, with defaults
                _limited.warning(f"act:{name}", "ROS 2 bridge: action %s: result not converted: %s", name, exc)
                return action_cls.Result()

        try:
            handle.execute(finish)
        except Exception as exc:  # the bridge is closing and the node is gone
            log.debug("ROS 2 bridge: action %s: goal %s not ended on the ROS 2 side: %s", name, goal_id, exc)

    # -- ROS 2 server, EMOS clients ------------------------------------------------------------
    def _offer_to_emos(self, name: str, ros_action: str) -> None:
        classes = emos_types_of(ros_action)
        if classes is None:
            self._refused.add(name)
            self._skip_once(name, f"ROS 2 action type {ros_action} has no EMOS counterpart", logging.INFO)
            return
        action_cls = self._action_class(name, ros_action)
        if action_cls is None:
            return
        import asyncio

        from rclpy.action import client as rclpy_client

        from emos.core.services import ActionServer

        ActionClient: Any = rclpy_client.ActionClient  # untyped
        client = ActionClient(self.node, action_cls, name, callback_group=self.group)

        def run(handle: Any) -> Any:  # a thread of the asyncio loop's executor
            return self._run_ros_goal(name, ros_action, client, action_cls, classes, handle)

        server = ActionServer(self.ctx, name, *classes, run, owner="ros2_bridge")
        try:
            asyncio.run_coroutine_threadsafe(server.start(), self.loop).result(timeout=10.0)
        except BaseException:
            client.destroy()
            raise
        self.to_emos[name] = _In(ros_action, server, client)
        log.info("ROS 2 bridge: action %s (%s) ROS 2 -> EMOS", name, ros_action)

    def _run_ros_goal(self, name: str, ros_action: str, client: Any, action_cls: Any, classes: tuple[type, type, type], handle: Any) -> Any:
        GoalStatus: Any = importlib.import_module("action_msgs.msg").GoalStatus

        def fail(why: str) -> ActionFailed:
            # The EMOS action server logs it, once, naming the bridge and the action: no second line here.
            return ActionFailed(f"ROS 2 action {name} ({ros_action}): goal {handle.goal_id}: {why}")

        def feedback(msg: Any) -> None:  # rclpy's executor thread
            try:
                handle.publish_feedback(to_emos(msg.feedback, classes[1]))
            except Exception as exc:
                _limited.warning(f"act-fb:{name}", "ROS 2 bridge: action %s: a feedback not passed on: %s", name, exc)

        missing_since: list[float] = []

        def gone() -> bool:
            """The server left the graph (checked while waiting)."""
            if self._closing.is_set():
                return True
            if client.server_is_ready():
                missing_since.clear()
                return False
            if not missing_since:
                missing_since.append(time.monotonic())
            return time.monotonic() - missing_since[0] >= GONE_AFTER_S

        deadline = time.monotonic() + ANSWER_TIMEOUT_S
        while not client.server_is_ready():  # discovered, but not matched yet (a server that just started)
            if time.monotonic() > deadline or self._closing.wait(0.05):
                raise fail(f"the server is not reachable (not matched within {ANSWER_TIMEOUT_S:g} s)")
        deadline = time.monotonic() + ANSWER_TIMEOUT_S
        sent = client.send_goal_async(to_ros(handle.goal, action_cls.Goal), feedback_callback=feedback)
        _wait(sent, lambda: gone() or time.monotonic() > deadline)
        if not sent.done():
            sent.cancel()
            raise fail("the server went away before answering the goal" if gone() else
                       f"the server did not answer the goal within {ANSWER_TIMEOUT_S:g} s")
        goal_handle = sent.result()
        if not goal_handle.accepted:
            raise fail("the server refused the goal")
        result_future = goal_handle.get_result_async()
        cancel_sent = False

        def stop_waiting() -> bool:
            nonlocal cancel_sent
            if handle.is_cancel_requested and not cancel_sent:
                cancel_sent = True
                goal_handle.cancel_goal_async()
            return gone()

        _wait(result_future, stop_waiting)
        if not result_future.done():
            raise fail("the server went away mid-goal" if not self._closing.is_set() else "the bridge is stopping")
        answer = result_future.result()
        result = to_emos(answer.result, classes[2])
        if answer.status == GoalStatus.STATUS_SUCCEEDED:
            return result
        if answer.status == GoalStatus.STATUS_CANCELED:
            handle.request_cancel()  # the EMOS caller gets ActionCanceled with this result
            return result
        raise fail("the server aborted the goal" if answer.status == GoalStatus.STATUS_ABORTED else f"the goal ended with status {answer.status}")

    # -- state ---------------------------------------------------------------------------------
    def summary(self) -> dict[str, str]:
        return {**{n: "emos->ros2" for n in self.to_ros}, **{n: "ros2->emos" for n in self.to_emos}}

    def close(self) -> None:
        import asyncio

        self._closing.set()
        for name, out in list(self.to_ros.items()):
            for goal_id in list(out.running):
                try:
                    out.client.cancel(goal_id)
                except Exception as exc:  # the EMOS server is stopping too
                    log.debug("ROS 2 bridge: action %s: goal %s not canceled: %s", name, goal_id, exc)
            out.server.destroy()
        for name, inn in list(self.to_emos.items()):
            try:
                asyncio.run_coroutine_threadsafe(inn.server.close(), self.loop).result(timeout=5.0)
            except Exception as exc:  # closing anyway
                log.debug("ROS 2 bridge: closing action %s: %s", name, exc)
            inn.client.destroy()
        self.to_ros.clear()
        self.to_emos.clear()
