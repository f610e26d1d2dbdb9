"""The UI component's configuration."""
from __future__ import annotations

from attrs import define, field

from emos.config import validators as base_validators
from emos.config.base import BaseComponentConfig


def _check_host(instance: object, attribute: object, value: str) -> None:
    if not isinstance(value, str) or not value:
        raise ValueError(f"UIConfig.host must be an address or host name, got {value!r}")


@define(kw_only=True)
class UIConfig(BaseComponentConfig):
    """Where the page is served and how fast it streams."""

    port: int = field(default=5001, validator=base_validators.in_range(min_value=1, max_value=65535))
    """TCP port of the page."""

    host: str = field(default="127.0.0.1", validator=_check_host)
    """Address to listen on (loopback by default; the access token is required on every address)."""

    token: str = field(default="", repr=False)  # a secret: kept out of reprs and log lines
    """Access token every request must carry, loopback included. Empty means "make one":
    ``enable_ui`` (or ``$EMOS_UI_TOKEN``) and ``UIComponent`` set a fresh random token; there is
    no way to switch it off."""

    jpeg_quality: int = field(default=80, validator=base_validators.in_range(min_value=10, max_value=100))
    """JPEG quality of camera streams (10-100)."""

    frames_in_flight: int = field(default=2, validator=base_validators.in_range(min_value=1, max_value=8))
    """Images sent to a browser before it confirms one: more hides network latency, fewer keeps
    the picture fresher on a slow browser. Frames that arrive meanwhile are dropped, never queued."""

    max_image_side: int = field(default=1280, validator=base_validators.in_range(min_value=64, max_value=8192))
    """Images larger than this (either side) are downscaled before encoding."""

    history: int = field(default=200, validator=base_validators.in_range(min_value=1, max_value=10000))
    """Text and number messages kept per topic for a page that connects later."""

    pose_rate: float = field(default=20.0, validator=base_validators.in_range(min_value=0.5, max_value=100.0))
    """Maximum rate (Hz) at which latest-value widgets (poses, paths, messages) are refreshed."""

    nice: int = field(default=5, validator=base_validators.in_range(min_value=0, max_value=19))
    """Scheduling niceness added to the UI's process: the page is best effort, so when the CPU is
    short the robot's components run first and the page shows fewer frames."""

    title: str = field(default="EMOS")
    """Page title (the recipe's name by default)."""

    # ---------------------------------------------------------------- security (docs/ui.md)
    tls: str = field(default="auto", validator=base_validators.in_(("auto", "on", "off")))
    """HTTPS: ``auto`` serves HTTPS off loopback and HTTP on loopback; ``on`` always; ``off``
    never (refused off loopback: tokens would cross the network in clear)."""

    certfile: str = field(default="")
    """The UI's own certificate (PEM). With ``keyfile``; without either, a self-signed one is made."""

    keyfile: str = field(default="")
    """The private key of ``certfile`` (PEM)."""

    keystore: str = field(default="")
    """An EMOS keystore (``emos security create-keystore``): the certificate of ``identity`` is used."""

    identity: str = field(default="ui")
    """The keystore identity whose certificate the UI serves."""

    serve_browser: bool = field(default=True)
    """``False``: headless, the REST and WebSocket API only (for fleet managers), no page."""

    pairing: bool = field(default=True)
    """Print a pairing code (and its QR code) that a device exchanges for a device token."""

    pairing_code: str = field(default="", repr=False)  # a secret: made by enable_ui
    """The current pairing code (made at start-up; a new one after each use)."""

    pairing_code_ttl_s: float = field(default=300.0, validator=base_validators.in_range(min_value=1.0, max_value=86400.0))
    """How long a pairing code is valid, in seconds (5 minutes by default; 1 s to a day). A code
    seen on a screen or photographed stops working by itself; when it expires a new one is made
    (``emos ui pair`` shows it). A used code is dead at once (single use)."""

    pairing_code_expires: float = field(default=0.0, repr=False)
    """When the current pairing code expires (UNIX time). Set by ``enable_ui`` when it prints the
    code, so the printed time holds and a restarted UI keeps it; 0: ``pairing_code_ttl_s`` from
    the moment the UI starts serving."""

    pairing_role: str = field(default="operator", validator=base_validators.in_(("viewer", "operator")))
    """The most a paired device gets: ``operator`` (may also ask for ``viewer``) or ``viewer``."""

    token_ttl_h: float = field(default=720.0, validator=base_validators.in_range(min_value=0.01, max_value=87600.0))
    """Lifetime of a device token, in hours (30 days by default)."""

    token_store: str = field(default="")
    """The device-token store; empty: ``<run dir>/ui.devices.json`` (tokens last one run). Give a
    path in a private directory of yours to keep paired devices across runs."""

    auth_failures_per_minute: int = field(default=30, validator=base_validators.in_range(min_value=1, max_value=10000))
    """Failed sign-ins (wrong tokens, wrong pairing codes) a client may make in a minute before
    it is refused (429); ten times as many from all clients together."""

    zones_map: str = field(default="")
    """A map_server YAML whose keepout and speed zones the page edits (drawn as polygons over the
    map; operators only), saved in its masks as `emos map zones` does. Empty: no zone editor."""

    allowed_hosts: list = field(factory=list)
    """Further names the page may be reached by (the ``Host`` header), e.g. a DNS name of the
    robot; its own addresses and host name are always allowed. Guards against DNS rebinding."""

    def uses_tls(self) -> bool:
        from emos.hosts import is_loopback

        return self.tls == "on" or (self.tls == "auto" and not is_loopback(self.host))
