"""``Launcher.enable_ui``: checked when the recipe calls it, added as a group at bringup."""
from __future__ import annotations

import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import attrs

from emos.actors.ui.auth import new_token
from emos.actors.ui.config import UIConfig
from emos.core.action_input import ActionInput
from emos.core.service_config import ServiceClientConfig
from emos.io.topic import Topic

ENV_TOKEN = "EMOS_UI_TOKEN"
UI_NAME = "ui"
# Set by `emos run --ui-https / --ui-cert / --ui-key / --ui-keystore` (tools/cli/run.py): the
# run's flags win over what the recipe says.
ENV_SETTINGS = {"EMOS_UI_TLS": "tls", "EMOS_UI_CERTFILE": "certfile", "EMOS_UI_KEYFILE": "keyfile", "EMOS_UI_KEYSTORE": "keystore",
                "EMOS_UI_HOST": "host"}


def _topics(role: str, items: Sequence[Any] | None, actions_allowed: bool = False) -> list[Any]:
    if items is None:
        return []
    if isinstance(items, (Topic, ActionInput, ServiceClientConfig)):
        items = [items]
    out = []
    for item in items:
        if not isinstance(item, Topic) and not (actions_allowed and isinstance(item, (ActionInput, ServiceClientConfig))):
            what = "Topic objects, a component's ui_main_action_input or ServiceClientConfig" if actions_allowed else "Topic objects"
            raise TypeError(f"enable_ui({role}=...) takes {what}, got {type(item).__name__} {item!r}")
        out.append(item)
    return out


def check_ui_request(inputs: Sequence[Any] | None, outputs: Sequence[Any] | None, port: int, host: str,
                     settings: dict[str, Any]) -> dict[str, Any]:
    known = {f.name for f in attrs.fields(UIConfig)} - {"port", "host"}
    unknown = sorted(set(settings) - known)
    if unknown:
        raise TypeError(f"enable_ui: unexpected argument(s) {', '.join(unknown)}; UI settings are {', '.join(sorted(known))}")
    settings = dict(settings)
    # The page can stop components and publish goals, and a loopback port is open to every
    # local user: the token is required on every address and cannot be switched off.
    if "token" in settings and (not isinstance(settings["token"], str) or not settings["token"]):
        raise ValueError(f"enable_ui(token={settings['token']!r}): the UI always requires an access token; leave token out "
                         f"to get a fresh random one (or set ${ENV_TOKEN}), or give a non-empty string")
    settings["token"] = settings.get("token") or os.environ.get(ENV_TOKEN) or new_token()
    for env, name in ENV_SETTINGS.items():
        if os.environ.get(env):
            if name == "host":
                host = os.environ[env]
            else:
                settings[name] = os.environ[env]
    config = UIConfig(port=port, host=host, **settings)  # validated here, at definition
    check_security(config)
    if config.pairing and not config.pairing_code:
        from emos.actors.ui.pairing import new_code

        # Made here, in the launcher's process (as the token): a restarted UI keeps it.
        config.pairing_code = new_code()
    ui_in, ui_out = _topics("inputs", inputs, actions_allowed=True), _topics("outputs", outputs)
    if not ui_in and not ui_out:
        raise ValueError("enable_ui: give the topics to show (outputs=[...]) and/or to send (inputs=[...])")
    return {"inputs": ui_in, "outputs": ui_out, "config": config}


def check_security(config: UIConfig) -> None:
    """Refuse, at definition, a UI that would be reachable from the network without HTTPS or
    with half a certificate."""
    from emos.hosts import is_loopback

    where = f"enable_ui(host={config.host!r}, port={config.port})"
    if not config.uses_tls() and not is_loopback(config.host):
        raise ValueError(f"{where}: off loopback the UI needs HTTPS (its tokens would cross the network in clear): "
                         "leave tls='auto' (a self-signed certificate is made) or give certfile/keyfile or keystore")
    if bool(config.certfile) != bool(config.keyfile):
        raise ValueError(f"{where}: give both certfile and keyfile (got certfile={config.certfile!r}, keyfile={config.keyfile!r})")
    if config.certfile and config.keystore:
        raise ValueError(f"{where}: give certfile/keyfile or keystore, not both")
    for name in ("certfile", "keyfile"):
        path = getattr(config, name)
        if path and not os.path.isfile(os.path.expanduser(path)):
            raise ValueError(f"{where}: {name} {path!r} is not a file")
    if config.zones_map and not os.path.isfile(os.path.expanduser(config.zones_map)):
        raise ValueError(f"{where}: zones_map {config.zones_map!r} is not a file (the map_server YAML whose zones the page edits)")
    if config.keystore and not os.path.isdir(os.path.expanduser(config.keystore)):
        raise ValueError(f"{where}: keystore {config.keystore!r} is not a directory (emos security create-keystore DIR makes one)")


def prepare_certificate(config: UIConfig) -> str:
    """Fill ``certfile``/``keyfile`` of a UI that serves HTTPS; returns the certificate's origin
    and fingerprint for the start-up lines ("" when the UI serves plain HTTP on loopback)."""
    if not config.uses_tls():
        return ""
    from emos.actors.ui import tls

    if config.certfile:
        origin = f"certificate {config.certfile}"
    elif config.keystore:
        cert, key = tls.from_keystore(config.keystore, config.identity)
        config.certfile, config.keyfile = str(cert), str(key)
        origin = f"certificate of {config.identity!r} from the keystore {config.keystore}"
    else:
        cert, key = tls.self_signed(tls.machine_names(config.host) + [str(h) for h in config.allowed_hosts])
        config.certfile, config.keyfile = str(cert), str(key)
        origin = f"self-signed certificate {cert}"
    tls.server_context(config.certfile, config.keyfile)  # a key that does not fit fails here, at bringup
    return f"{origin}, SHA-256 {tls.fingerprint(Path(config.certfile))}"


def run_log_file() -> str | None:
    """The log `emos run` keeps of this run (its first lines name our pid), if there is one."""
    folder = Path(os.environ.get("EMOS_HOME") or Path.home() / "emos").expanduser() / "logs"
    mine = f"pid {os.getpid()} "
    try:
        logs = sorted(folder.glob("*.log"), key=lambda p: p.stat().st_mtime, reverse=True)[:20]
    except OSError:
        return None
    for path in logs:
        try:
            with open(path, errors="replace") as f:
                if mine in f.read(2048):
                    return str(path)
        except OSError:
            continue
    return None


def add_ui(launcher: Any, request: dict[str, Any]) -> None:
    """Add the UI component as its own supervised group, in its own process."""
    from emos.actors.ui.component import UIComponent, page_url

    components = [c for p in launcher._packages for c in p.components]
    if any(c.component_name == UI_NAME for c in components):
        raise ValueError(f"enable_ui: a component is already named {UI_NAME!r}; the UI needs that name")
    config = request["config"]
    if config.title == "EMOS" and sys.argv and sys.argv[0]:
        config.title = f"EMOS · {os.path.splitext(os.path.basename(sys.argv[0]))[0]}"
    topics = [t for t in request["inputs"] if isinstance(t, Topic)]
    actions = [a for a in request["inputs"] if isinstance(a, ActionInput)]
    services = [s for s in request["inputs"] if isinstance(s, ServiceClientConfig)]
    from emos.actors.ui.system_view import describe_graph

    certificate = prepare_certificate(config)
    if config.pairing and not config.pairing_code_expires:
        # From the moment it is printed (below): the printed time holds, and a restarted UI keeps it.
        config.pairing_code_expires = time.time() + config.pairing_code_ttl_s
    graph = describe_graph(components, list(getattr(launcher, "_events_actions", [])))
    ui = UIComponent(ui_inputs=topics, ui_outputs=request["outputs"], ui_actions=actions, ui_services=services, components=components,
                     config=config, component_name=UI_NAME, graph=graph, log_file=run_log_file())
    launcher.add_pkg(components=[ui], package_name="ui", multiprocessing=True)
    # Printed once, here: this link signs the browser in. The UI's own log line (and every
    # restart's) names the token file instead of repeating the token.
    print(f"EMOS UI: {page_url(config)}", flush=True)
    if certificate:
        print(f"EMOS UI: HTTPS with the {certificate}", flush=True)
    if config.pairing:
        from emos.actors.ui.pairing import lifetime_text, pairing_url, terminal_qr, until_text

        link = pairing_url(page_url(config, with_token=False, reachable=True), config.pairing_code)
        qr = terminal_qr(link)
        until = f"valid until {until_text(config.pairing_code_expires)} ({lifetime_text(config.pairing_code_ttl_s)}), single use"
        print(f"EMOS UI: pair a device: open {link}, or enter the code {config.pairing_code} at /pair "
              f"({until}; `emos ui pair` shows the current one)" + (f"\n{qr}\nEMOS UI: the QR code above is {until}" if qr else ""),
              flush=True)
