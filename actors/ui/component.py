"""``UIComponent``: the web page of a recipe, as a supervised component of its own.

It subscribes to the topics the page shows (each message is handed to its hub, see
:mod:`emos.actors.ui.streams`), publishes what the user enters on the page, and serves both over
HTTP and a websocket from its own event loop. ``Launcher.enable_ui`` creates it.
"""
from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from emos.actors.ui.config import UIConfig
from emos.actors.ui.widgets import output_kind
from emos.core.action_input import ActionInput
from emos.core.component import BaseComponent
from emos.core.conventions import resolve_config
from emos.core.service_config import ServiceClientConfig
from emos.io.topic import Topic

BIND_RETRY_S = 2.0


class UIComponent(BaseComponent):
    @classmethod
    def config_class(cls) -> type[UIConfig]:
        return UIConfig

    def __init__(
        self,
        ui_inputs: Sequence[Topic] = (),
        ui_outputs: Sequence[Topic] = (),
        components: Sequence[BaseComponent] = (),
        ui_actions: Sequence[ActionInput] = (),
        config: UIConfig | None = None,
        ui_services: Sequence[Any] = (),
        component_name: str = "ui",
        graph: dict[str, Any] | None = None,
        log_file: str | None = None,
    ) -> None:
        """``ui_inputs``: topics the page publishes to (text boxes, buttons, goals on the map).
        ``ui_outputs``: topics the page shows. ``components``: whose settings the page offers.
        ``ui_actions``: actions the page sends goals to (``component.ui_main_action_input``).
        ``graph``: the system graph (system_view.describe_graph); ``log_file``: the run's log."""
        # Resolved before BaseComponent does it: the token is made here, ahead of super().__init__.
        config = resolve_config(component_name, type(self).__name__, config, UIConfig)
        if not config.token:
            # Made here, in the launcher's process, so that a restarted UI process keeps it and
            # open pages (their cookie) stay signed in.
            from emos.actors.ui.auth import new_token

            config.token = new_token()
        shown, controls = list(ui_outputs), list(ui_inputs)
        both = sorted({t.name for t in shown} & {t.name for t in controls})
        if both:
            # The page would receive its own messages back; say so instead of looping.
            raise ValueError(f"enable_ui: topic(s) {', '.join(both)} are both inputs and outputs of the UI")
        super().__init__(component_name=component_name, inputs=shown, outputs=controls, config=config,
                         trigger=shown if shown else 1.0)
        self.config: UIConfig
        self._settings_of = {c.component_name: c.config for c in components if c is not self}
        for a in ui_actions:
            if not isinstance(a, ActionInput):
                raise TypeError(f"UIComponent ui_actions must be ActionInput objects, got {type(a).__name__}")
        self._actions = {a.name: a for a in ui_actions}
        for s in ui_services:
            if not isinstance(s, ServiceClientConfig):
                raise TypeError(f"UIComponent ui_services must be ServiceClientConfig objects, got {type(s).__name__}")
        self._services = {s.name: s for s in ui_services}
        self._graph, self._log_file = graph, log_file
        self._server: Any = None
        self._start_task: Any = None
        self._stop_task: Any = None  # held until done: the loop keeps only weak references to tasks
        self._listening = False

    # -- lifecycle -------------------------------------------------------------------------------
    def custom_on_configure(self) -> None:
        from emos.actors.ui.server import UIServer
        from emos.actors.ui.streams import make_hub
        from emos.core.control import control_socket
        from emos.core.priority import lower_priority
        from emos.core.services import service_socket
        from emos.transport.context import encode_name

        node = self.node
        lower_priority(self.config.nice, self.component_name)  # best effort: the robot's components run first
        hubs, first_map = [], True
        for t in self.in_topics:
            kind = output_kind(t.msg_type.__name__)
            hubs.append(make_hub(t.name, t.msg_type.__name__, kind, self.config, overlay=kind == "map" and not first_map))
            first_map = first_map and kind != "map"
        self._hubs = {h.topic: h for h in hubs}
        self._server = UIServer(
            self.config, hubs, {t.name: t.msg_type.__name__ for t in self.out_topics}, self._settings_of,
            publish=self.publish, control_socket=lambda name: Path(control_socket(node.ctx, name)),
            supervisor_socket=node.supervisor_socket, own_name=self.component_name,
            actions=self._actions, action_socket=lambda name: Path(service_socket(node.ctx, name)), services=self._services,
            token_file=Path(node.ctx.run_dir) / f"{encode_name(self.component_name)}.token",
            devices_file=Path(self.config.token_store).expanduser() if self.config.token_store
            else Path(node.ctx.run_dir) / f"{encode_name(self.component_name)}.devices.json",
            pairing_file=Path(node.ctx.run_dir) / f"{encode_name(self.component_name)}.pairing",
            base_url=page_url(self.config, with_token=False, reachable=True), graph=self._graph,
            log_file=Path(self._log_file) if self._log_file else None,
        )
        self._listening = False

    def custom_on_activate(self) -> None:
        import asyncio

        if self._start_task is None:
            self._start_task = asyncio.ensure_future(self._serve())

    async def _serve(self) -> None:
        """Listen and serve. A taken port does not stop the robot: the UI reports the failure
        (health and a log line naming the address) and tries again every ``BIND_RETRY_S``."""
        import asyncio

        failures = 0
        server = self._server
        while server is not None and server is self._server:
            try:
                server.bind()
                await server.start()
                break
            except ValueError as exc:  # a UI that must not serve as configured (plain HTTP off loopback, a bad certificate)
                self.get_logger().error("[%s] not serving: %s", self.component_name, exc)
                server.close_listener()
                self.health_status.set_fail_system(message=str(exc))
                self.node.publish_status()
                return
            except OSError as exc:
                failures += 1
                if failures == 1 or failures % 30 == 0:
                    self.get_logger().error("[%s] %s (tried %d times; retrying every %g s)", self.component_name, exc, failures, BIND_RETRY_S)
                # An address held by someone else is an external fault (SYSTEM_FAILURE), not a
                # broken UI: a COMPONENT_FAILURE would make the supervisor restart it in a loop
                # until the restart intensity stopped the whole robot.
                self.health_status.set_fail_system(message=str(exc))
                self.node.publish_status()
                await asyncio.sleep(BIND_RETRY_S)
        else:
            return
        self._listening = True
        self.health_status.set_healthy()
        # The link with the token was printed once at bringup; logs (and restarts) get the file.
        self.get_logger().info("[%s] page at %s (access token in %s)", self.component_name, page_url(self.config, with_token=False),
                               server.token_file)

    def custom_on_shutdown(self) -> None:
        self._stop_server()

    def custom_on_cleanup(self) -> None:
        self._stop_server()

    def _stop_server(self) -> None:
        import asyncio

        if self._server is not None:
            server, self._server = self._server, None
            server.close_listener()
            try:
                self._stop_task = asyncio.ensure_future(server.stop())
            except RuntimeError:  # no loop any more: the listener is closed, the rest goes with the process
                pass
        if self._start_task is not None:
            self._start_task.cancel()
        self._start_task = None
        self._listening = False

    # -- every shown message -----------------------------------------------------------------------
    def _execution_step(self, msg: Any = None, topic: Topic | None = None, **kwargs: Any) -> None:
        if msg is not None and topic is not None:
            hub = self._hubs.get(topic.name)
            if hub is not None:
                hub.push(msg, time.time_ns())
        if self._listening:
            self.health_status.set_healthy()


def page_url(config: UIConfig, with_token: bool = True, reachable: bool = False) -> str:
    """The page's address; ``with_token``: the link that signs the browser in (print it once).
    ``reachable``: for a UI bound to every address, one of this machine's addresses (for the
    pairing QR code) instead of a placeholder."""
    from urllib.parse import quote

    host = config.host
    if host in ("0.0.0.0", "::"):
        host = _lan_address() if reachable else ""
        host = host or "<this machine's address>"
    host = f"[{host}]" if ":" in host and not host.startswith("<") else host
    scheme = "https" if config.uses_tls() else "http"
    return f"{scheme}://{host}:{config.port}/" + (f"?token={quote(config.token, safe='')}" if with_token and config.token else "")


def _lan_address() -> str:
    """An IPv4 address of this machine other devices can likely reach (the default route's)."""
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.connect(("192.0.2.1", 9))  # TEST-NET: nothing is sent, the kernel just picks the route
            addr = str(s.getsockname()[0])
        except OSError:
            return ""
    return "" if addr.startswith("127.") else addr
