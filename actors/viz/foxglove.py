"""``FoxgloveBridgeComponent``: the Foxglove bridge as a supervised component of a recipe.

``launcher.enable_foxglove(port=8765)`` adds one, in its own process: it follows every topic of
the run (new ones too) and serves them on a Foxglove WebSocket server; if it crashes, the
supervisor restarts it like any other component. ``emos viz`` serves the same bridge from
outside a running system.
"""
from __future__ import annotations

from typing import Any

from attrs import define, field

from emos.config import validators
from emos.config.base import BaseComponentConfig
from emos.core.component import BaseComponent
from emos.core.conventions import resolve_config


def _port(instance: Any, attribute: Any, value: Any) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 65535:
        raise ValueError(f"FoxgloveConfig.port must be an int in 0..65535 (0: any free port), got {value!r}")


def _host(instance: Any, attribute: Any, value: Any) -> None:
    if not isinstance(value, str) or not value.strip():
        raise ValueError(f"FoxgloveConfig.host must be a non-empty address such as '127.0.0.1', got {value!r}")


def _names(instance: Any, attribute: Any, value: Any) -> None:
    if not isinstance(value, list) or not all(isinstance(v, str) and v for v in value):
        raise ValueError(f"FoxgloveConfig.{attribute.name} must be a list of topic names or wildcards, got {value!r}")


def _token(instance: Any, attribute: Any, value: Any) -> None:
    from emos.interop.foxglove_gate import make_token

    try:
        make_token(value)
    except ValueError as exc:
        raise ValueError(f"FoxgloveConfig.token: {exc}") from None


def _origins(instance: Any, attribute: Any, value: Any) -> None:
    from emos.interop.foxglove_gate import OriginPattern

    if not isinstance(value, list):
        raise ValueError(f"FoxgloveConfig.allow_origins must be a list of origins such as 'https://example.com:*', got {value!r}")
    for origin in value:
        try:
            OriginPattern(origin)
        except (ValueError, AttributeError) as exc:
            raise ValueError(f"FoxgloveConfig.allow_origins: {exc}") from None


def _distribution(instance: Any, attribute: Any, value: Any) -> None:
    from emos.interop.ros2_cdr import DISTRIBUTIONS

    if value not in DISTRIBUTIONS:
        raise ValueError(f"FoxgloveConfig.distribution must be one of {', '.join(DISTRIBUTIONS)}, got {value!r}")


@define(kw_only=True)
class FoxgloveConfig(BaseComponentConfig):
    """``host``/``port``: where the WebSocket server listens (127.0.0.1 keeps it on this machine;
    any other host requires a ``token``). ``token``: required of every client as
    ``ws://host:port/?token=...``; ``"auto"`` makes a random one, logged once with the URL.
    ``allow_origins``: browser origins accepted besides Foxglove's app and localhost pages.
    ``topics``/``exclude``: names or wildcards (empty ``topics``: all). ``loop_rate``: how often (Hz)
    new messages are forwarded."""

    loop_rate: float = field(default=50.0, validator=validators.in_range(min_value=1e-9, max_value=1e9))
    host: str = field(default="127.0.0.1", validator=_host)
    port: int = field(default=8765, validator=_port)
    topics: list = field(factory=list, validator=_names)
    exclude: list = field(factory=list, validator=_names)
    distribution: str = field(default="humble", validator=_distribution)
    token: str | None = field(default=None, validator=_token)
    allow_origins: list = field(factory=list, validator=_origins)


def _check_exposure(component_name: str, config: FoxgloveConfig) -> None:
    """At definition time, not at activation: a bridge open to the network needs a token."""
    from emos.hosts import is_loopback

    if config.token is None and not is_loopback(config.host):
        raise ValueError(f"component {component_name!r}: FoxgloveConfig.host {config.host!r} is not a loopback address, so "
                         "every machine that reaches it would get every topic (camera frames included): set "
                         "FoxgloveConfig.token (a string of 8+ URL characters, or 'auto')")


class FoxgloveBridgeComponent(BaseComponent):
    """Serves the run's topics to Foxglove (see :mod:`emos.interop.foxglove_bridge`)."""

    @classmethod
    def config_class(cls) -> type[FoxgloveConfig]:
        return FoxgloveConfig

    def __init__(self, component_name: str = "foxglove_bridge", config: FoxgloveConfig | None = None, **kwargs: Any) -> None:
        # Resolved before BaseComponent does it: the exposure check needs it first.
        config = resolve_config(component_name, type(self).__name__, config, FoxgloveConfig)
        _check_exposure(component_name, config)
        super().__init__(component_name, config=config, **kwargs)
        self.config: FoxgloveConfig = config
        self.bridge: Any = None

    def custom_on_activate(self) -> None:
        from emos.hosts import is_loopback
        from emos.interop.foxglove_bridge import FoxgloveBridge

        cfg = self.config
        self.bridge = FoxgloveBridge(self.node.ctx, cfg.host, cfg.port, cfg.topics or None, cfg.exclude,
                                     distribution=cfg.distribution, use_waker=False, token=cfg.token,
                                     allow_origins=cfg.allow_origins)
        if not is_loopback(cfg.host):
            self.get_logger().warning("Foxglove: listening on %s port %d: every machine that reaches it and knows the token gets "
                                      "every topic, camera frames included; the traffic is not encrypted", cfg.host, self.bridge.port)
        # A token the user chose is not repeated in the log; an "auto" one is shown once, or nobody could use it.
        self.get_logger().info("Foxglove: %s%s", self.bridge.url(with_token=cfg.token == "auto"),
                               " (token required)" if cfg.token not in (None, "auto") else "")

    def _execution_step(self, **kwargs: Any) -> None:
        if self.bridge is not None:
            self.bridge.step()
        self.health_status.set_healthy()

    def custom_on_deactivate(self) -> None:
        self._close()

    def custom_on_shutdown(self) -> None:
        self._close()

    def _close(self) -> None:
        if self.bridge is not None:
            bridge, self.bridge = self.bridge, None
            bridge.close()
