"""Zenoh access rules and TLS configuration derived from a recipe.

Roles (each an identity of the keystore, matched by its certificate's common name):

* **robot** (``--identity``): the hosts that run the recipe. They publish the components'
  outputs and statuses, subscribe to their inputs, outputs and statuses, serve their services
  and actions, the run's status tree (``_run_``) and component control (``_ctl_``).
* **operator**: subscribes to everything the robot publishes, publishes the recipe's
  *external* inputs only (inputs that no component publishes: goals, commands from outside; never
  ``/cmd_vel`` of a recipe whose DriveManager publishes it), calls services and actions, reads
  the status tree.
* **viewer**: subscribes and reads the status tree; publishes and calls nothing.

Zenoh's access control judges each message a session exchanges with a remote peer by that peer's
certificate common name. A rule about subject X therefore names messages *from* X (ingress) and
*to* X (egress); both are derived: "X may publish T" is ingress ``put`` from X on T's key plus
egress ``declare_subscriber`` to X (so that X learns where to send), and "X may subscribe T" is
the reverse. Everything else is denied (``default_permission: deny``), and so is every peer
without a certificate of the keystore's CA (mutual TLS, TLS the only link protocol).

Two exceptions, both metadata: every identity may announce publishers (the liveliness tokens
``emos/<group>/<topic>/_pub_/...`` EMOS publishers declare) and query the group's liveliness
(discovery, ``emos topic list --network``). That is what lets the robot see, and log, an
identity announcing a publisher on a topic it may not publish (:mod:`emos.security.watch`).

One file per identity (the same rules; its own certificate and endpoints), JSON5 with comments,
meant to be read and edited by hand.
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from emos.security.keystore import KeystoreError, check_name, load_identity
from emos.security.recipe_graph import RecipeGraph

__all__ = ["Roles", "derive_permissions", "zenoh_config", "render_json5", "write_policies", "policy_dir", "ROLES"]

ROLES = ("robot", "operator", "viewer")
_PUB_IN = ["put", "delete", "reply", "liveliness_token", "declare_queryable"]  # what a publisher sends (incl. a latched cache)
_SUB_IN = ["declare_subscriber", "query", "declare_liveliness_subscriber", "liveliness_query"]  # what a subscriber sends


@dataclass
class Roles:
    robots: list[str]
    operators: list[str] = field(default_factory=list)
    viewers: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        if not self.robots:
            raise KeystoreError("a policy needs at least one robot identity (--identity NAME): the hosts that run the recipe")
        seen: dict[str, str] = {}
        for role, names in (("robot", self.robots), ("operator", self.operators), ("viewer", self.viewers)):
            for name in names:
                check_name(name)
                if name in seen:
                    raise KeystoreError(f"identity {name!r} is given two roles ({seen[name]} and {role}): one role per identity")
                seen[name] = role

    def role_of(self, name: str) -> str:
        for role, names in (("robot", self.robots), ("operator", self.operators), ("viewer", self.viewers)):
            if name in names:
                return role
        raise KeystoreError(f"identity {name!r} has no role in this policy")

    def all(self) -> list[str]:
        return [*self.robots, *self.operators, *self.viewers]


def _topic_key(topic: str, group: str) -> str:
    from emos.transport.zenoh_net import topic_key

    return topic_key(topic, group)


def _service_key(name: str, group: str) -> str:
    from emos.transport.zenoh_rpc import service_key

    return service_key(name, group)


def derive_permissions(graph: RecipeGraph, roles: Roles) -> dict[str, dict[str, list[str]]]:
    """Per identity: ``{"publish": topics, "subscribe": topics, "serve": services, "call": services}``
    (topic and service names; run-level keys such as the status tree are added by :func:`zenoh_config`)."""
    published = sorted(set(graph.outputs) | set(graph.statuses))
    readable = sorted(set(published) | set(graph.inputs))
    perms: dict[str, dict[str, list[str]]] = {}
    for name in roles.robots:
        perms[name] = {"publish": published, "subscribe": readable, "serve": graph.services, "call": graph.services}
    for name in roles.operators:
        perms[name] = {"publish": graph.external_inputs, "subscribe": readable, "serve": [], "call": graph.services}
    for name in roles.viewers:
        perms[name] = {"publish": [], "subscribe": readable, "serve": [], "call": []}
    return perms


def _rule(rule_id: str, flow: str, messages: list[str], keys: list[str]) -> dict[str, Any]:
    return {"id": rule_id, "permission": "allow", "flows": [flow], "messages": messages, "key_exprs": sorted(set(keys))}


def _topic_keys(topics: list[str], group: str) -> list[str]:
    keys: list[str] = []
    for t in topics:
        k = _topic_key(t, group)
        # the topic; the publisher tokens EMOS declares under it; zenoh.ext's keys of a latched
        # topic (``@adv`` is a verbatim chunk: no ``**`` matches it, so it is named)
        keys += [k, f"{k}/_pub_/**", f"{k}/@adv/**"]
    return keys


def access_control(graph: RecipeGraph, roles: Roles, group: str) -> dict[str, Any]:
    """Zenoh 1.x ``access_control`` for ``graph`` and ``roles``."""
    perms = derive_permissions(graph, roles)
    root = f"emos/{group}"
    rules: list[dict[str, Any]] = []
    subjects: list[dict[str, Any]] = []
    policies: list[dict[str, Any]] = []
    for name in roles.all():
        p, role = perms[name], roles.role_of(name)
        ids: list[str] = []

        def add(label: str, flow: str, messages: list[str], keys: list[str], *, _ids: list[str] = ids, _name: str = name) -> None:
            if keys:
                rule = _rule(f"{_name}: {label} ({flow})", flow, messages, keys)
                rules.append(rule)
                _ids.append(rule["id"])

        pub, sub = _topic_keys(p["publish"], group), _topic_keys(p["subscribe"], group)
        add("publishes its topics", "ingress", _PUB_IN, pub)
        add("publishes its topics", "egress", _SUB_IN, pub)
        add("subscribes to its topics", "ingress", _SUB_IN, sub)
        add("subscribes to its topics", "egress", _PUB_IN, sub)
        serve = [_service_key(s, group) for s in p["serve"]]
        call = [_service_key(s, group) for s in p["call"]]
        run_serve = [f"{root}/_run_/**", f"{root}/_ctl_/**"] if role == "robot" else []
        run_call = [f"{root}/_run_/**"] + ([f"{root}/_ctl_/**"] if role == "robot" else [])
        add("serves its services", "ingress", ["declare_queryable", "reply"], serve + run_serve)
        add("serves its services", "egress", ["query"], serve + run_serve)
        add("calls services", "ingress", ["query"], call + run_call)
        add("calls services", "egress", ["declare_queryable", "reply"], call + run_call)
        # Metadata every identity may exchange (see the module doc): publisher announcements and discovery.
        add("announces publishers (metadata, watched)", "ingress", ["liveliness_token"], [f"{root}/**/_pub_/**"])
        add("discovers topics", "ingress", ["liveliness_query", "declare_liveliness_subscriber"], [f"{root}/**"])
        add("discovers topics", "egress", ["liveliness_token", "reply"], [f"{root}/**/_pub_/**"])
        subjects.append({"id": name, "cert_common_names": [name]})
        policies.append({"id": f"{role} {name}", "subjects": [name], "rules": ids})
    return {"enabled": True, "default_permission": "deny", "rules": rules, "subjects": subjects, "policies": policies}


def tls_config(keystore: str | os.PathLike[str], identity: str, verify_name: bool = True) -> dict[str, Any]:
    cert, key, ca = load_identity(keystore, identity)
    return {
        "root_ca_certificate": str(ca),
        "listen_certificate": str(cert), "listen_private_key": str(key),
        "connect_certificate": str(cert), "connect_private_key": str(key),
        "enable_mtls": True,  # a peer without a certificate of this CA cannot open a link
        "verify_name_on_connect": bool(verify_name),  # the listener's certificate must name the address dialled (its SANs)
        "close_link_on_expiration": True,  # a link ends when the peer's certificate expires
    }


def zenoh_config(graph: RecipeGraph, roles: Roles, identity: str, keystore: str | os.PathLike[str], group: str,
                 listen: list[str] | None = None, connect: list[str] | None = None, verify_name: bool = True) -> dict[str, Any]:
    """The whole Zenoh configuration of ``identity``: peer mode, TLS endpoints only, mutual TLS
    with its certificate, no multicast scouting, the access rules."""
    roles.role_of(identity)
    for e in [*(listen or []), *(connect or [])]:
        if not str(e).startswith("tls/"):
            raise KeystoreError(f"endpoint {e!r} is not a TLS endpoint (tls/HOST:PORT): a secure run listens and connects over TLS only")
    return {
        "mode": "peer",
        "listen": {"endpoints": list(listen or [])},
        "connect": {"endpoints": list(connect or [])},
        "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": True}},
        "transport": {"link": {"protocols": ["tls"], "tls": tls_config(keystore, identity, verify_name)},
                      "shared_memory": {"enabled": False}},
        # Read by this process only: the access rules allow no peer any key under "@".
        "adminspace": {"enabled": True, "permissions": {"read": True, "write": False}},
        "access_control": access_control(graph, roles, group),
    }


def render_json5(config: dict[str, Any], graph: RecipeGraph, roles: Roles, identity: str, group: str) -> str:
    """The configuration as JSON5 with a header saying where it came from and how to edit it."""
    lines = [
        f"// Zenoh configuration of identity '{identity}' ({roles.role_of(identity)}) for recipe {graph.recipe}",
        "// written by `emos security policy`; edit freely (Zenoh 1.x JSON5: https://zenoh.io/docs/manual/access-control/).",
        f"// Group: {group} (topic /x is key emos/{group}/x). Roles: robot {roles.robots}, operator {roles.operators}, viewer {roles.viewers}.",
        "// Everything not allowed below is denied; a peer without a certificate of this keystore's CA cannot connect.",
        "// To let an identity publish one more topic, add its key (and KEY/_pub_/**) to that identity's",
        "// 'publishes its topics' rules; to add an identity, add a subject (its certificate CN) and a policy.",
        "// Other hosts: add their tls/HOST:PORT endpoints to connect.endpoints; the HOST must be in their certificate's SANs.",
        "// Services include those the components create when they configure (read from their code, nothing was run).",
        *(f"// NOT DERIVED: {note}" for note in graph.notes),
    ]
    return "\n".join(lines) + "\n" + _dump(config, "") + "\n"


def _dump(value: Any, indent: str) -> str:
    """JSON, one key per line, lists of plain values on one line: short enough to read and edit."""
    inner = indent + "  "
    if isinstance(value, dict) and value:
        items = [f"{inner}{json.dumps(k)}: {_dump(v, inner)}" for k, v in value.items()]
        return "{\n" + ",\n".join(items) + f"\n{indent}}}"
    if isinstance(value, list) and any(isinstance(v, (dict, list)) for v in value):
        return "[\n" + ",\n".join(inner + _dump(v, inner) for v in value) + f"\n{indent}]"
    return json.dumps(value)


def policy_dir(keystore: str | os.PathLike[str], recipe: str | os.PathLike[str]) -> Path:
    """Where ``emos security policy`` writes a recipe's files by default: ``KEYSTORE/policies/<recipe stem>/``."""
    return Path(keystore).expanduser().absolute() / "policies" / Path(recipe).stem


def write_policies(graph: RecipeGraph, roles: Roles, keystore: str | os.PathLike[str], group: str, out_dir: str | os.PathLike[str],
                   listen: list[str] | None = None, connect: list[str] | None = None, verify_name: bool = True,
                   force: bool = False) -> list[Path]:
    """One file per identity, ``out_dir/<identity>.json5`` (0600). Robots listen on ``listen``,
    every identity connects to ``connect``. Existing files are kept unless ``force`` (they may
    hold hand edits)."""
    out = Path(out_dir)
    out.mkdir(mode=0o700, parents=True, exist_ok=True)
    written: list[Path] = []
    import re

    # A robot's other processes (its file is shared by the run) listen on ports of their own and
    # reach the one holding the fixed port through its loopback address (in every identity's
    # SANs when made by `emos security create-identity`).
    local = [f"tls/localhost:{m.group(1)}" for e in listen or [] if (m := re.search(r":(\d+)$", str(e))) and m.group(1) != "0"]
    for name in roles.all():
        role = roles.role_of(name)
        conf = zenoh_config(graph, roles, name, keystore, group, listen=listen if role == "robot" else [],
                            connect=[*(connect or []), *(local if role == "robot" else [])], verify_name=verify_name)
        text = render_json5(conf, graph, roles, name, group)
        path = out / f"{name}.json5"
        flags = os.O_WRONLY | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC | (os.O_TRUNC if force else os.O_EXCL)
        try:
            fd = os.open(path, flags, 0o600)
        except FileExistsError:
            raise KeystoreError(f"{path} already exists (it may hold hand edits): give --force to replace it") from None
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            os.fchmod(f.fileno(), 0o600)
            f.write(text)
        written.append(path)
    return written
