"""Services across the bridge, both ways, for the service types both sides have.

A service type is shared when EMOS registers its parts as ``pkg/msg/X_Request`` and
``pkg/msg/X_Response`` (``std_srvs/msg/Trigger_Request``, ...) and rclpy can import ``pkg.srv.X``.

* An EMOS component's service (a socket under ``<run>/srv``) is offered on the ROS 2 graph under
  its name, as ``pkg/srv/X``; a ROS 2 client's call runs the EMOS service and returns its answer.
* A ROS 2 service (a server other than this bridge) is offered to EMOS components under its name;
  an EMOS :class:`~emos.core.services.ServiceClient` call goes to the ROS 2 server.

Requests and responses are copied field by field (the service types shared so far are flat).
An EMOS caller whose ROS 2 server fails or does not answer within ``CALL_TIMEOUT_S`` gets an
error reply naming the service; a ROS 2 caller whose EMOS service fails gets the response type's
defaults (ROS 2 has no error reply), with one rate-limited log line naming the service.
"""
from __future__ import annotations

import asyncio
import importlib
import logging
import threading
from typing import Any

import attrs

from emos.interop.ros2 import env
from emos.msgs.registry import registered_types
from emos.ratelimit import RateLimitedLog
from emos.transport.context import RunContext, decode_name

log = logging.getLogger("emos.ros2")
_limited = RateLimitedLog(log, interval=10.0)
CALL_TIMEOUT_S = 10.0


def emos_types_of(ros_srv: str) -> tuple[type, type] | None:
    """EMOS (request, response) classes of a ROS 2 service type ``pkg/srv/X``, if registered."""
    package, _, name = ros_srv.partition("/srv/")
    types = registered_types()
    req, resp = types.get(f"{package}/msg/{name}_Request"), types.get(f"{package}/msg/{name}_Response")
    return (req, resp) if req is not None and resp is not None else None


def _copy(src: Any, cls: type) -> Any:
    """An instance of ``cls`` (ours, attrs) or of an rclpy class with ``src``'s fields."""
    if attrs.has(cls):
        return cls(**{f.name: getattr(src, f.name) for f in attrs.fields(cls)})
    out = cls()
    for f in attrs.fields(type(src)):
        setattr(out, f.name, getattr(src, f.name))
    return out


class ServiceBridge:
    """The services part of a :class:`~emos.interop.ros2.bridge.Ros2Bridge` (same node and run)."""

    def __init__(self, ctx: RunContext, node: Any, wanted: Any, skip_once: Any):
        from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup

        self.ctx, self.node, self.wanted, self._skip_once = ctx, node, wanted, skip_once
        # Calls to EMOS services block their executor thread: one at a time, beside the topics'
        # group; the answers of ROS 2 servers to our clients must come in meanwhile.
        groups: Any = (MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup)  # rclpy's constructors are untyped
        self.serve_group = groups[0]()
        self.client_group = groups[1]()
        self.to_ros: dict[str, Any] = {}  # EMOS service name -> rclpy service
        self.to_emos: dict[str, Any] = {}  # ROS 2 service name -> (EMOS ServiceServer, rclpy client)
        self._emos_clients: dict[str, Any] = {}
        self._describe_failed: set[str] = set()
        self._refused: set[str] = set()
        self.loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self.loop.run_forever, name="ros2-services", daemon=True)
        self._thread.start()

    # -- discovery (the forwarder thread) ------------------------------------------------------
    def discover(self) -> None:
        srv_dir = self.ctx.run_dir / "srv"
        if srv_dir.is_dir():
            for sock in srv_dir.glob("*.sock"):
                name = "/" + decode_name(sock.name[:-5]).lstrip("/")
                if name not in self.to_ros and name not in self.to_emos and name not in self._refused and self.wanted(name):
                    self._guarded(name, self._offer_to_ros, name, sock)
        for name, types in self.node.get_service_names_and_types():
            if name in self.to_ros or name in self.to_emos or name in self._refused or not self.wanted(name) or len(types) != 1:
                continue
            pair = emos_types_of(types[0])
            if pair is None:
                continue  # rcl_interfaces' parameter services and other types we lack: nothing to say per node
            self._guarded(name, self._offer_to_emos, name, types[0], pair)

    def _guarded(self, name: str, offer: Any, *args: Any) -> None:
        """One service that cannot be offered (a name ROS 2 refuses, ...) is left out, once, with a
        line naming it; the bridge and the other services go on."""
        try:
            offer(*args)
        except Exception as exc:
            self._refused.add(name)
            self._skip_once(name, f"service not offered: {type(exc).__name__}: {exc}")

    def _srv_class(self, name: str, ros_srv: str) -> Any:
        package, _, cls_name = ros_srv.partition("/srv/")
        try:
            env.prepare_package(package)
            return getattr(importlib.import_module(f"{package}.srv"), cls_name)
        except (ImportError, AttributeError) as exc:
            self._skip_once(name, f"{ros_srv} needs the ROS 2 package {package}, which rclpy cannot import ({exc})")
            return None

    def _offer_to_ros(self, name: str, sock: Any) -> None:
        from emos.core.rpc import RpcClient, RpcError

        try:
            with RpcClient(sock, timeout=2.0) as rpc:
                described = rpc.call("describe")
        except (OSError, RpcError) as exc:  # not up yet, or an action (no "describe" of this kind)
            if name not in self._describe_failed:
                self._describe_failed.add(name)
                log.debug("ROS 2 bridge: service %s not described: %s", name, exc)
            return
        if not isinstance(described, dict) or "request" not in described or "response" not in described:
            return  # an action server
        found = [(t, cls) for t, cls in registered_types().items() if cls.__name__ == described["request"] and t.endswith("_Request")]
        if not found:
            self._skip_once(name, f"EMOS service type {described['request']} has no ROS 2 counterpart", logging.INFO)
            return
        ros_srv = found[0][0].replace("/msg/", "/srv/")[: -len("_Request")]
        pair = emos_types_of(ros_srv)
        srv_cls = self._srv_class(name, ros_srv)
        if pair is None or srv_cls is None:
            return
        from emos.core.services import ServiceClient

        client = ServiceClient(name, pair[0], pair[1], ctx=self.ctx, timeout=CALL_TIMEOUT_S)
        self._emos_clients[name] = client

        def serve(request: Any, response: Any) -> Any:
            try:
                answer = client.call(_copy(request, pair[0]))
                return _copy(answer, srv_cls.Response)
            except Exception as exc:  # the EMOS side failed: ROS 2 has no error reply
                _limited.warning(f"srv:{name}", "ROS 2 bridge: service %s (%s): the EMOS service failed: %s", name, ros_srv, exc)
                return response

        self.to_ros[name] = self.node.create_service(srv_cls, name, serve, callback_group=self.serve_group)
        log.info("ROS 2 bridge: service %s (%s) EMOS -> ROS 2", name, ros_srv)

    def _offer_to_emos(self, name: str, ros_srv: str, pair: tuple[type, type]) -> None:
        srv_cls = self._srv_class(name, ros_srv)
        if srv_cls is None:
            return
        from emos.core.services import ServiceServer

        client = self.node.create_client(srv_cls, name, callback_group=self.client_group)
        loop = self.loop

        async def call(request: Any) -> Any:
            future = client.call_async(_copy(request, srv_cls.Request))
            waiter: asyncio.Future[Any] = loop.create_future()

            def settle(result: Any, error: BaseException | None) -> None:
                if waiter.done():
                    return
                if error is not None:
                    waiter.set_exception(error)
                else:
                    waiter.set_result(result)

            def done(f: Any) -> None:  # rclpy's executor thread
                try:
                    loop.call_soon_threadsafe(settle, f.result(), None)
                except Exception as exc:
                    loop.call_soon_threadsafe(settle, None, exc)

            future.add_done_callback(done)
            try:
                answer = await asyncio.wait_for(waiter, CALL_TIMEOUT_S)
            except TimeoutError:
                future.cancel()
                # EMOS callers get an error reply (ROS 2 servers cannot give one).
                raise TimeoutError(f"ROS 2 service {name} ({ros_srv}) did not answer within {CALL_TIMEOUT_S:g} s") from None
            return _copy(answer, pair[1])

        server = ServiceServer(self.ctx, name, pair[0], pair[1], call, owner="ros2_bridge")
        asyncio.run_coroutine_threadsafe(server.start(), loop).result(timeout=10.0)
        self.to_emos[name] = (server, client)
        log.info("ROS 2 bridge: service %s (%s) ROS 2 -> EMOS", name, ros_srv)

    def close(self) -> None:
        for server, client in self.to_emos.values():
            try:
                asyncio.run_coroutine_threadsafe(server.close(), self.loop).result(timeout=5.0)
            except Exception as exc:  # closing anyway
                log.debug("ROS 2 bridge: closing a service: %s", exc)
            self.node.destroy_client(client)
        for srv in self.to_ros.values():
            self.node.destroy_service(srv)
        for c in self._emos_clients.values():
            c.close()
        self.to_emos.clear()
        self.to_ros.clear()
        self.loop.call_soon_threadsafe(self.loop.stop)
        self._thread.join(timeout=5.0)
        self.loop.close()
