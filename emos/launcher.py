"""``Launcher``: bring a recipe's components up under supervision and keep them up.

    launcher = Launcher(multi_processing=True)
    launcher.add_pkg(components=[camera, detector], activate_all_components_on_start=True)
    launcher.bringup()   # blocks until SIGINT/SIGTERM, then stops everything in reverse order

Each ``add_pkg`` call becomes one supervised group (its own supervisor under the root). The
supervisor lives in ``emos.supervisor`` and is imported only when ``bringup`` runs.
"""
from __future__ import annotations

import logging
import os
import sys
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, TypedDict

from emos import lockstep
from emos.core.component import BaseComponent
from emos.frontends import load_frontend

if TYPE_CHECKING:
    from emos.events.action import Action
    from emos.events.event import Event

# The Monitor reads a message this long after it is woken (see Launcher.__init__). Measured with
# `emos bench events` (docs/benchmarks-history.md, "The Monitor reads last"): with one core busy it keeps
# the topic's p95 within 10 % (1.5x without), for +0.7 ms of event latency.
DEFAULT_MONITOR_DEFER_MS = 0.5
MAX_MONITOR_DEFER_MS = 20.0

log = logging.getLogger("emos.launcher")

# Set by `emos run --duration`: recipes stop by themselves after that many seconds.
_RUN_DURATION: float | None = None


class SupervisionDefaults(TypedDict):
    """``Launcher.default_policy``: the restart policy of every group that sets none of its own."""
    strategy: str
    max_restarts: int
    max_seconds: float


class Launcher:
    last_exit_code: int | None = None  # of the last bringup in this process, for `emos run`

    def __init__(
        self,
        config_file: str | None = None,
        multi_processing: bool = False,
        activate_all_components_on_start: bool = True,
        enable_monitoring: bool = True,
        heartbeat_timeout: float = 2.0,
        max_restarts: int = 5,
        max_seconds: float = 10.0,
        strategy: str = "one_for_one",
        stop_timeout: float = 5.0,
        fallback_reset_after: float = 10.0,
        monitor_nice: int = 5,
        monitor_defer_ms: float = DEFAULT_MONITOR_DEFER_MS,
        **kwargs: Any,
    ) -> None:
        """``heartbeat_timeout``: seconds without a status message before a component counts as
        hung and is killed. ``max_restarts`` in ``max_seconds``: restart intensity of every group
        (unless ``add_pkg`` overrides it) and of the root, which restarts whole groups. ``strategy``:
        one_for_one, one_for_all or rest_for_one. ``stop_timeout``: seconds between SIGTERM and SIGKILL.
        ``fallback_reset_after``: seconds a component must stay healthy before its fallback retry
        budgets (and a give-up) reset. ``monitor_nice``: niceness (0-19) added to the Monitor's
        process in multi-process runs, so that evaluating events yields the CPU to the components
        that read the same topics (0 keeps it at the components' priority). ``monitor_defer_ms``:
        how long the Monitor waits after being woken by a message before it reads it, so that on
        a machine short of cores the components woken by the same message run first (0: at once;
        it adds as much to every event's latency).
        """
        if kwargs:
            raise TypeError(f"Launcher: unexpected argument(s) {', '.join(sorted(kwargs))}")
        self.config_file = config_file
        self.multi_processing = bool(multi_processing)
        self.activate_all_components_on_start = activate_all_components_on_start
        self.enable_monitoring = enable_monitoring
        for name, value in (("heartbeat_timeout", heartbeat_timeout), ("max_seconds", max_seconds), ("stop_timeout", stop_timeout),
                            ("fallback_reset_after", fallback_reset_after)):
            if isinstance(value, bool) or not isinstance(value, (int, float)) or value <= 0:
                raise ValueError(f"Launcher: {name} must be a positive number of seconds, got {value!r}")
        if isinstance(max_restarts, bool) or not isinstance(max_restarts, int) or max_restarts < 0:
            raise ValueError(f"Launcher: max_restarts must be an int >= 0, got {max_restarts!r}")
        if isinstance(monitor_nice, bool) or not isinstance(monitor_nice, int) or not 0 <= monitor_nice <= 19:
            raise ValueError(f"Launcher: monitor_nice must be an int in 0..19, got {monitor_nice!r}")
        self.monitor_nice = monitor_nice
        if isinstance(monitor_defer_ms, bool) or not isinstance(monitor_defer_ms, (int, float)) or not 0 <= monitor_defer_ms <= MAX_MONITOR_DEFER_MS:
            raise ValueError(f"Launcher: monitor_defer_ms must be a number of milliseconds in 0..{MAX_MONITOR_DEFER_MS:g}, got {monitor_defer_ms!r}")
        self.monitor_defer_ms = float(monitor_defer_ms)
        self.heartbeat_timeout = heartbeat_timeout
        self.stop_timeout = stop_timeout
        self.fallback_reset_after = float(fallback_reset_after)
        self.default_policy: SupervisionDefaults = {"strategy": strategy, "max_restarts": max_restarts, "max_seconds": max_seconds}
        self._packages: list[Any] = []
        self._events_actions: list[Any] = []  # (Event, [Action]) pairs
        self._fallback_policies: dict[str, Any] = {}
        self.fallback_rate: float | None = None
        self.exit_code: int | None = None
        self.exit_reason = ""
        self.system: Any = None
        self._shared_wiring: list[tuple[str, dict[str, Any]]] = []
        self._shared_config: dict[str, Any] = {}
        self._ui: dict[str, Any] | None = None
        self._monitor: BaseComponent | None = None  # add_pkg(monitor=...): a Cortex

    def add_pkg(
        self,
        components: Sequence[BaseComponent],
        package_name: str | None = None,
        executable_entry_point: str | None = None,
        events_actions: dict[Event, Action | list[Action]] | None = None,
        multiprocessing: bool | None = None,
        activate_all_components_on_start: bool | None = None,
        ros_log_level: str | None = None,
        strategy: str | None = None,
        max_restarts: int | None = None,
        max_seconds: float | None = None,
        restart: str = "permanent",
        monitor: BaseComponent | None = None,
    ) -> None:
        """Add a group of components. ``package_name`` and ``executable_entry_point`` are accepted
        so ROS recipes port unchanged; EMOS needs no entry point to run a component in a process.
        ``monitor``: a component that serves as the launcher's monitor (a ``Cortex``): it gets the
        run's health changes and event/fallback outcomes as observations (its
        ``serve_as_monitor``) and runs in a group of its own, so that its crashes never restart,
        stop or end anything else (see docs/cortex.md)."""
        from emos.supervisor.system import Package, SupervisionPolicy

        components = list(components)
        if monitor is not None:
            self._set_monitor(monitor, components)
        if not components:
            raise ValueError("add_pkg: components must not be empty")
        for c in components:
            if not isinstance(c, BaseComponent):
                raise TypeError(f"add_pkg: components must be BaseComponent instances, got {type(c).__name__} {c!r}")
        known = {c.component_name for p in self._packages for c in p.components}
        dupes = sorted(known & {c.component_name for c in components})
        if dupes:
            raise ValueError(f"add_pkg: component name(s) already added: {', '.join(dupes)}")
        if self.config_file:
            for c in components:
                c.configure(self.config_file)
        if events_actions:
            from emos.supervisor.orchestration import normalize_events_actions

            self._events_actions.extend(normalize_events_actions(events_actions))
        if ros_log_level:
            level = getattr(logging, ros_log_level.upper(), None)
            if not isinstance(level, int):
                raise ValueError(f"add_pkg: ros_log_level must be debug, info, warn, error or fatal; got {ros_log_level!r}")
            for c in components:
                c.get_logger().setLevel(level)
        policy = SupervisionPolicy(
            strategy=strategy or self.default_policy["strategy"],
            max_restarts=self.default_policy["max_restarts"] if max_restarts is None else max_restarts,
            max_seconds=self.default_policy["max_seconds"] if max_seconds is None else max_seconds,
            restart=restart,
        )
        self._packages.append(Package(
            components=components,
            multiprocessing=self.multi_processing if multiprocessing is None else bool(multiprocessing),
            activate=self.activate_all_components_on_start if activate_all_components_on_start is None else activate_all_components_on_start,
            policy=policy,
            name=package_name or f"group{len(self._packages)}",
        ))

    def _set_monitor(self, monitor: BaseComponent, components: list[BaseComponent]) -> None:
        # Duck-typed: the core knows no monitor class (Cortex is an actor, a layer above).
        if not isinstance(monitor, BaseComponent) or not callable(getattr(monitor, "serve_as_monitor", None)):
            raise TypeError(f"add_pkg(monitor=...): expected a component that can serve as the monitor (a Cortex, with "
                            f"serve_as_monitor), got {type(monitor).__name__} {monitor!r}")
        if self._monitor is not None and self._monitor is not monitor:
            raise ValueError(f"add_pkg(monitor=...): this launcher has a monitor already ({self._monitor.component_name!r})")
        if monitor in components:
            raise ValueError(f"add_pkg: {monitor.component_name!r} is the monitor; pass it as monitor= only (it runs in a group of its own)")
        known = {c.component_name for p in self._packages for c in p.components}
        if monitor.component_name in known:
            raise ValueError(f"add_pkg(monitor=...): component name {monitor.component_name!r} already added")
        self._monitor = monitor

    def _monitor_package(self) -> Any:
        """The monitor's own group: restarted when it crashes (its own intensity), and dropped,
        not escalated, when it crashes more than that: the run goes on without it."""
        from emos.supervisor.monitor import OUTCOMES_TOPIC
        from emos.supervisor.system import Package, SupervisionPolicy

        monitor = self._monitor
        assert monitor is not None
        if self.config_file:
            monitor.configure(self.config_file)
        monitor.serve_as_monitor(outcomes_topic=OUTCOMES_TOPIC)  # type: ignore[attr-defined]
        return Package(components=[monitor], multiprocessing=self.multi_processing, activate=True,
                       policy=SupervisionPolicy(strategy="one_for_one", max_restarts=self.default_policy["max_restarts"],
                                                max_seconds=self.default_policy["max_seconds"]),
                       name=f"{monitor.component_name}_monitor", group_restart="temporary")

    # -- Kompass-style conveniences: shared wiring and robot description ---------------------------
    def kompass(self, components: Sequence[BaseComponent], multiprocessing: bool | None = None, **kwargs: Any) -> None:
        """Add navigation components as one group (Kompass' name for ``add_pkg``)."""
        self.add_pkg(components=components, package_name=kwargs.pop("package_name", "kompass"),
                     multiprocessing=multiprocessing, **kwargs)

    def inputs(self, **topics: Any) -> None:
        """Wire an input key for every component that has it: ``launcher.inputs(location=odom)``.
        Applied at bringup, so components added later get it too; a key no component has fails then."""
        self._shared_wiring.append(("inputs", topics))

    def outputs(self, **topics: Any) -> None:
        """Wire an output key for every component that has it."""
        self._shared_wiring.append(("outputs", topics))

    @property
    def robot(self) -> Any:
        return self._shared_config.get("robot")

    @robot.setter
    def robot(self, value: Any) -> None:
        """The robot description (``RobotConfig``) given to every component whose config has ``robot``."""
        self._shared_config["robot"] = value

    @property
    def frames(self) -> Any:
        return self._shared_config.get("frames")

    @frames.setter
    def frames(self, value: Any) -> None:
        """The coordinate frames (``RobotFrames``) given to every component whose config has ``frames``."""
        self._shared_config["frames"] = value

    def _apply_shared(self) -> None:
        from emos.core.keyed import KeyedComponent, key_name

        components = [c for p in self._packages for c in p.components]
        for role, topics in self._shared_wiring:
            for raw_key, topic in topics.items():
                key = key_name(raw_key)
                takers = [c for c in components if isinstance(c, KeyedComponent) and key in c._allowed(role)]
                if not takers:
                    raise ValueError(f"Launcher.{role}({key}=...): no component added to this launcher has the {role[:-1]} key {key!r}")
                for c in takers:
                    getattr(c, role)(**{key: topic})
        for name, value in self._shared_config.items():
            if value is None:
                continue
            for c in components:
                if hasattr(c.config, name):
                    setattr(c.config, name, value)  # validated by the component's attrs config
        for c in components:
            missing = c.missing_required() if isinstance(c, KeyedComponent) else []
            if missing:
                raise ValueError(f"component {c.component_name!r} ({type(c).__name__}) has no topic for required {', '.join(missing)}")

    def enable_ui(self, inputs: Sequence[Any] | None = None, outputs: Sequence[Any] | None = None,
                  port: int = 5001, host: str = "127.0.0.1", **settings: Any) -> None:
        """Serve a web page for this recipe: ``outputs`` are shown, ``inputs`` can be sent from it.
        Every request needs the access token, loopback included: ``token=...``, ``$EMOS_UI_TOKEN``,
        or a fresh random one. It is printed once at start-up as the link
        ``http://127.0.0.1:5001/?token=...`` and kept in ``<run dir>/ui.token`` (mode 0600) while
        the UI runs; it cannot be switched off. Further ``UIConfig`` fields may be given by name."""
        # The UI is an actor: found through its entry point (emos.frontends), not imported here.
        self._ui = load_frontend("ui").request(inputs=inputs, outputs=outputs, port=port, host=host, **settings)

    def enable_foxglove(self, port: int = 8765, host: str = "127.0.0.1", **config: Any) -> None:
        """Serve every topic live to Foxglove on ``ws://host:port``, from a supervised component
        (``foxglove_bridge``) in its own process. ``config``: more ``FoxgloveConfig`` fields
        (``topics``, ``exclude``, ``loop_rate``, ``distribution``, ``token``, ``allow_origins``);
        a host other than loopback requires ``token``."""
        frontend = load_frontend("foxglove")
        frontend.add(self, frontend.request(port=port, host=host, **config))

    # Launcher-wide fallback policies: for every component without its own handler of that level
    # (see emos.core.fallbacks for the order). Run by the supervisor (emos.supervisor.fallback_driver).
    def _policy(self, key: str, action_name: str, max_retries: int | None) -> None:
        from emos.supervisor.orchestration import check_policy

        self._fallback_policies[key] = check_policy(key, action_name, max_retries)

    def on_fail(self, action_name: str, max_retries: int | None = None) -> None:
        """Catch-all for every component: ``action_name`` is restart, stop, start or a method name."""
        self._policy("on_fail", action_name, max_retries)

    def on_component_fail(self, action_name: str, max_retries: int | None = None) -> None:
        self._policy("on_component_fail", action_name, max_retries)

    def on_algorithm_fail(self, action_name: str, max_retries: int | None = None) -> None:
        self._policy("on_algorithm_fail", action_name, max_retries)

    def on_system_fail(self, action_name: str, max_retries: int | None = None) -> None:
        self._policy("on_system_fail", action_name, max_retries)

    def bringup(self, duration: float | None = None) -> int:
        """Run until SIGINT/SIGTERM (or ``duration`` seconds); stop in order; return the exit code.

        A non-zero code (the supervisor gave up, or a component failed to start) also ends the
        script with that code when it runs as ``python recipe.py``.
        """
        from emos.supervisor.system import System, SystemOptions

        if not self._packages:
            raise RuntimeError("Launcher.bringup: no components; call add_pkg(components=[...]) first")
        if self._monitor is not None and not any(p.name == f"{self._monitor.component_name}_monitor" for p in self._packages):
            self._packages.append(self._monitor_package())  # last: it starts after what it watches
        self._apply_shared()
        consumers = None
        if lockstep.requested():  # `emos run --lockstep`: before the UI and bridges join (they follow the wall clock)
            consumers = lockstep.apply([c for p in self._packages for c in p.components], monitor=self._monitor)
        if self._ui is not None:
            load_frontend("ui").add(self, self._ui)
        # `emos run --ros2` / emos.transport.select.use_ros2(): the ROS 2 bridge (an actor, found
        # through its entry point), unless the recipe added one itself.
        if os.environ.get("EMOS_ROS2") == "1" and not any(c.component_name == "ros2_bridge" for p in self._packages for c in p.components):
            ros2 = load_frontend("ros2")
            ros2.add(self, ros2.request())
        from emos.supervisor.orchestration import Orchestration

        if self.fallback_rate is not None and (isinstance(self.fallback_rate, bool) or not isinstance(self.fallback_rate, (int, float)) or self.fallback_rate <= 0):
            raise ValueError(f"Launcher.fallback_rate must be a positive number of Hz, got {self.fallback_rate!r}")
        orchestration = Orchestration(events_actions=list(self._events_actions), policies=dict(self._fallback_policies),
                                      fallback_rate=self.fallback_rate, reset_after=self.fallback_reset_after,
                                      monitor_nice=self.monitor_nice, monitor_defer_ms=self.monitor_defer_ms,
                                      report_outcomes=self._monitor is not None)
        if not logging.getLogger().handlers:
            logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s", stream=sys.stderr)
        if consumers is not None:
            log.info("lockstep: the simulator waits every tick for %s", ", ".join(consumers))
        options = SystemOptions(
            heartbeat_timeout=self.heartbeat_timeout, stop_timeout=self.stop_timeout, duration=duration or _RUN_DURATION,
            max_restarts=self.default_policy["max_restarts"], max_seconds=self.default_policy["max_seconds"],
        )
        self.system = System(self._packages, options, orchestration)
        code: int = self.system.run()  # System.run's exit code (the supervisor is typed as Any here: a layer above)
        self.exit_code, self.exit_reason = code, self.system.exit_reason
        Launcher.last_exit_code = code
        # One write: `emos run` copies stdout and stderr to its log through two tee processes,
        # and unbuffered (PYTHONUNBUFFERED) print writes the text and its newline apart, so the
        # next log line could land inside the summary's last line.
        sys.stdout.write(self.system.summary() + "\n")
        sys.stdout.flush()
        log.info("bringup ended (exit code %d): %s", code, self.exit_reason)
        if code != 0 and os.environ.get("EMOS_RUN_CLI") != "1":
            raise SystemExit(code)
        return code
