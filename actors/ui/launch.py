"""``Launcher.enable_ui``: checked when the recipe calls it, added as a group at bringup."""
from __future__ import annotations

import os
import sys
from collections.abc import Sequence
from typing import Any

import attrs

from emos.actors.ui.auth import new_token
from emos.actors.ui.config import UIConfig
from emos.core.action_input import ActionInput
from emos.core.service_config import ServiceClientConfig
from emos.io.topic import Topic

ENV_TOKEN = "EMOS_UI_TOKEN"
UI_NAME = "ui"


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
    config = UIConfig(port=port, host=host, **settings)  # validated here, at definition
    ui_in, ui_out = _topics("inputs", inputs, actions_allowed=True), _topics("outputs", outputs)
    if not ui_in and not ui_out:
        raise ValueError("enable_ui: give the topics to show (outputs=[...]) and/or to send (inputs=[...])")
    return {"inputs": ui_in, "outputs": ui_out, "config": config}


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
    ui = UIComponent(ui_inputs=topics, ui_outputs=request["outputs"], ui_actions=actions, ui_services=services, components=components,
                     config=config, component_name=UI_NAME)
    launcher.add_pkg(components=[ui], package_name="ui", multiprocessing=True)
    # Printed once, here: this link signs the browser in. The UI's own log line (and every
    # restart's) names the token file instead of repeating the token.
    print(f"EMOS UI: {page_url(config)}", flush=True)
