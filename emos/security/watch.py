"""Log an identity's attempts to publish what the access rules deny it.

Zenoh's access control drops a denied message without telling the application: the subscriber
sees nothing, and Zenoh's own trace (``RUST_LOG=zenoh::net::routing::interceptor=trace``, on
stderr) only records, per key, that permissions were cached as unauthorized. What *can* be
observed, and is authenticated: an EMOS publisher declares a liveliness token
``emos/<group>/<topic>/_pub_/<type>/<publisher>`` (the rules let every identity announce one:
metadata), and Zenoh's admin space of our own session says which peer declared a token
(``@/<zid>/peer/token/<key>``) and which certificate that peer's link authenticated with
(``@/<zid>/session/transport/unicast/<peer>/link/<id>``: ``auth_identifier``, the certificate's
common name). :class:`SecurityWatch` joins the two: for every announced publisher on a topic
whose ``put`` the rules do not allow that identity, it logs a WARNING naming the identity, the
peer, the topic and the publisher, rate-limited per (identity, topic) with
:class:`emos.ratelimit.RateLimitedLog`. The messages themselves are still dropped by Zenoh.

A peer that is not EMOS (a raw Zenoh program) announces nothing: its denied messages are
dropped just the same, unlogged. ``emos run --secure`` runs one watch per run, in its own
process (``python -m emos.security.watch CONFIG``; Zenoh's threads must not be forked).
"""
from __future__ import annotations

import json
import logging
import os
import queue
import signal
import sys
import threading
from typing import Any

from emos.ratelimit import RateLimitedLog
from emos.transport.zenoh_net import ROUTING_TURNS

log = logging.getLogger("emos.security")
_PUB_MARK = "/_pub_/"

__all__ = ["SecurityWatch", "allowed_puts"]


def allowed_puts(access_control: dict[str, Any]) -> dict[str, list[str]]:
    """Per certificate common name: the key expressions of the allow rules that let it ``put``
    (ingress), from an ``access_control`` section (generated or edited by hand)."""
    rules = {r.get("id"): r for r in access_control.get("rules") or [] if isinstance(r, dict)}
    subjects = {s.get("id"): s for s in access_control.get("subjects") or [] if isinstance(s, dict)}
    out: dict[str, list[str]] = {}
    for policy in access_control.get("policies") or []:
        names = [cn for sid in policy.get("subjects") or [] for cn in (subjects.get(sid) or {}).get("cert_common_names") or []]
        keys = []
        for rid in policy.get("rules") or []:
            r = rules.get(rid) or {}
            flows = r.get("flows") or ["ingress", "egress"]
            if r.get("permission") == "allow" and "ingress" in flows and "put" in (r.get("messages") or []):
                keys += [str(k) for k in r.get("key_exprs") or []]
        for cn in names:
            out.setdefault(str(cn), []).extend(keys)
    return out


class SecurityWatch:
    """Watches ``session``'s group for publishers announced by identities the rules in
    ``access_control`` do not let publish there (see the module doc)."""

    def __init__(self, session: Any, access_control: dict[str, Any], group: str, interval: float = 10.0):
        import zenoh

        self._zenoh = zenoh
        self.session = session
        self.allowed = {cn: [zenoh.KeyExpr(k) for k in keys] for cn, keys in allowed_puts(access_control).items()}
        self.root = f"emos/{group}"
        self.denied_seen = 0
        self._log = RateLimitedLog(log, interval=interval)
        self._queue: queue.Queue[str | None] = queue.Queue(maxsize=1024)  # bounded: peers can mint tokens
        self._closing = threading.Event()
        self._worker = threading.Thread(target=self._work, name="emos-security-watch", daemon=True)
        self._worker.start()
        # Zenoh's thread only queues: the admin-space queries below must not run inside its callback.
        with ROUTING_TURNS:
            self._sub = session.liveliness().declare_subscriber(f"{self.root}/**", self._on_token, history=True)

    def _on_token(self, sample: Any) -> None:
        key = str(sample.key_expr)
        if _PUB_MARK in key and not self._closing.is_set() and sample.kind == self._zenoh.SampleKind.PUT:
            try:
                self._queue.put_nowait(key)
            except queue.Full:
                self._log.warning("queue-full", "security watch: too many publisher announcements at once; some are not checked")

    def _permitted(self, cn: str, topic_key: str) -> bool:
        ke = self._zenoh.KeyExpr(topic_key)
        return any(allowed.includes(ke) for allowed in self.allowed.get(cn, []))

    def _admin(self, selector: str) -> list[tuple[str, Any]]:
        out = []
        with ROUTING_TURNS:  # no declaration of this process while the reply is routed (zenoh_net)
            replies = list(self.session.get(selector, timeout=2.0))
        for reply in replies:
            if reply.ok is None:
                continue
            try:
                out.append((str(reply.ok.key_expr), json.loads(reply.ok.payload.to_bytes())))
            except ValueError:
                continue  # the admin space's graph is text, not JSON
        return out

    def _identities(self, zid: str) -> set[str]:
        me = self.session.info.zid()
        return {str(v.get("auth_identifier")) for _, v in self._admin(f"@/{me}/session/transport/unicast/{zid}/link/*")
                if isinstance(v, dict) and v.get("auth_identifier")}

    def check(self, token_key: str) -> list[str]:
        """Check one announced publisher token; returns the identities that announced it without
        permission (each logged)."""
        from emos.transport.context import decode_name

        topic_key, _, rest = token_key.partition(_PUB_MARK)
        type_name, _, publisher = rest.partition("/")
        try:
            type_name, publisher = decode_name(type_name).lstrip("/"), decode_name(publisher).lstrip("/")
        except Exception:  # noqa: BLE001 - a name EMOS did not encode: shown as it came
            pass
        me = self.session.info.zid()
        peers: list[str] = []
        for _, value in self._admin(f"@/{me}/peer/token/{token_key}"):
            if isinstance(value, dict):
                peers += [str(p) for group in ("peers", "routers", "clients") for p in value.get(group) or []]
        denied = []
        for zid in peers:
            for cn in self._identities(zid) or {"<no certificate>"}:
                if self._permitted(cn, topic_key):
                    continue
                denied.append(cn)
                self.denied_seen += 1
                topic = "/" + topic_key[len(self.root) + 1:] if topic_key.startswith(self.root + "/") else topic_key
                self._log.warning(
                    ("denied", cn, topic_key),
                    "security: identity %r (Zenoh peer %s) announced a publisher on topic %s (type %s, publisher %r), which the "
                    "access rules do not allow it to publish: Zenoh's access control drops its messages", cn, zid, topic, type_name, publisher)
        return denied

    def _work(self) -> None:
        while True:
            key = self._queue.get()
            if key is None or self._closing.is_set():
                return
            try:
                self.check(key)
            except Exception as exc:  # noqa: BLE001 - a watch that dies would look fine and log nothing
                self._log.warning(("error", type(exc).__name__), "security watch: checking %s failed: %s", key, exc)

    def close(self) -> None:
        """Stop the checks, then undeclare the subscriber. In that order: Zenoh (1.10) can
        deadlock undeclaring a liveliness subscriber while another thread of the session waits
        for an admin-space reply (the undeclare holds the routing tables' lock that delivering
        the reply needs, and waits for a lock the reply holds), so no query may be in flight."""
        self._closing.set()
        try:
            self._queue.put_nowait(None)
        except queue.Full:
            pass  # the worker sees _closing after its current check
        # Each check is a few admin queries of at most 2 s each.
        self._worker.join(timeout=30.0)
        if self._worker.is_alive():
            log.warning("security watch: a check did not end in 30 s; the subscriber is left to the session's close")
            return
        try:
            with ROUTING_TURNS:
                self._sub.undeclare()
        except Exception as exc:  # noqa: BLE001 - the session may be closed already
            log.debug("security watch: undeclaring: %s", exc)


def main(argv: list[str] | None = None) -> int:
    """``python -m emos.security.watch CONFIG``: watch until the parent process (the run) exits."""
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 1:
        print("usage: python -m emos.security.watch ZENOH_CONFIG", file=sys.stderr)
        return 2
    from emos.core.prctl import PR_SET_PDEATHSIG, prctl

    parent = os.getppid()
    try:
        prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
    except OSError:
        pass
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s", stream=sys.stderr)
    import zenoh

    from emos.transport.zenoh_config import load_config
    from emos.transport.zenoh_net import _open_file, net_group

    acl = json.loads(load_config(zenoh, argv[0]).get_json("access_control"))
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    # Started before the run's components, the watch usually holds the file's listening port, so
    # the other hosts' peers connect to it directly: the admin space names only direct peers.
    session = _open_file(zenoh, argv[0])
    watch = SecurityWatch(session, acl, net_group())
    log.info("security watch: watching emos/%s for publishers the access rules deny (%s)", net_group(), argv[0])
    print("ready", flush=True)  # the run starts its components after this line (secure_run.start_watch)
    try:
        while not stop.wait(1.0):
            if os.getppid() != parent:
                break
    finally:
        watch.close()
        session.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
