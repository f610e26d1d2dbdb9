"""The supervisor's status across hosts: what ``emos status --remote`` reads.

A run that uses Zenoh (``emos run --zenoh CONFIG``) starts one small helper process next to its
supervisor: a Zenoh queryable on ``emos/<group>/_run_/<run id>`` that answers each query with
the supervision tree, asked of the supervisor's control socket (the same ``tree`` that
``emos status`` prints). A separate process, started with exec (``python -m``), because the
supervisor forks component processes and a Zenoh session's threads must not be forked; it dies
with the supervisor (parent-death signal) and when the run's socket goes away.

The same helper repeats every component's ``<name>/status`` over Zenoh
(:mod:`emos.transport.zenoh_status_mirror`), so a Monitor on another host can react to it, and
serves every component's control (:mod:`emos.transport.zenoh_control`), so that Monitor's
actions can reach it.
"""
from __future__ import annotations

import json
import logging
import os
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

from emos.transport.context import RunContext
from emos.transport.zenoh_config import ENV_ZENOH_CONFIG
from emos.transport.zenoh_control import ControlBridges, control_enabled
from emos.transport.zenoh_net import KEY_ROOT, net_group, session
from emos.transport.zenoh_status_mirror import StatusMirror

log = logging.getLogger("emos.transport.zenoh")
RUN_MARK = "_run_"
NAMES_EVERY_S = 2.0


def status_key(run_id: str = "*", group: str | None = None) -> str:
    return f"{KEY_ROOT}/{group or net_group()}/{RUN_MARK}/{run_id}"


def start_status_bridge(run_dir: Path, run_id: str) -> subprocess.Popen[bytes] | None:
    """Start the helper if this run uses Zenoh (``$EMOS_ZENOH_CONFIG``); None otherwise."""
    if not os.environ.get(ENV_ZENOH_CONFIG):
        return None
    control_enabled()  # a bad $EMOS_NET_CONTROL fails here, in the supervisor, not in the helper
    return subprocess.Popen([sys.executable, "-m", "emos.transport.zenoh_status", str(run_dir), run_id, str(os.getpid())], stdin=subprocess.DEVNULL)


def stop_status_bridge(proc: subprocess.Popen[bytes] | None) -> None:
    if proc is None or proc.poll() is not None:
        return
    proc.terminate()
    try:
        proc.wait(3.0)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def remote_status(config_path: str | None = None, timeout: float = 3.0) -> list[dict[str, Any]]:
    """The supervision trees of every run of the group that answers within ``timeout``."""
    out = []
    for reply in session(config_path).get(status_key(), timeout=timeout):
        if reply.ok is None:
            log.warning("emos status --remote: a run answered with an error: %s", reply.err.payload.to_bytes()[:200])
            continue
        try:
            data = json.loads(reply.ok.payload.to_bytes())
        except ValueError as exc:
            log.warning("emos status --remote: an answer on %s that is not JSON: %s", reply.ok.key_expr, exc)
            continue
        if isinstance(data, dict) and "tree" in data:
            data["key"] = str(reply.ok.key_expr)
            out.append(data)
    return sorted(out, key=lambda d: str(d.get("run_id")))


def _serve(run_dir: Path, run_id: str) -> None:
    from emos.core.rpc import RpcClient

    key = status_key(run_id)
    sock = run_dir / "supervisor.sock"

    def answer(query: Any) -> None:
        with query:
            try:
                with RpcClient(sock, timeout=5.0) as rpc:
                    data = rpc.call("tree")
                query.reply(key, json.dumps(data, default=str))
            except Exception as exc:  # noqa: BLE001 - the caller gets the reason
                query.reply_err(json.dumps({"error": f"{type(exc).__name__}: {exc}"}))

    queryable = session().declare_queryable(key, lambda q: threading.Thread(target=answer, args=(q,), daemon=True).start())
    mirror: StatusMirror | None = None
    ctx = RunContext(run_id, run_dir, owner=False)
    controls = ControlBridges(ctx) if control_enabled() else None
    next_lookup = 0.0
    try:
        mirror = StatusMirror(ctx)
        while sock.exists():
            if time.monotonic() >= next_lookup:
                # The supervisor builds its tree after starting us: look again now and then.
                names = _worker_names(sock)
                mirror.watch(names)
                if controls is not None and names:  # an unanswered tree (starting, stopping) keeps what we serve
                    controls.watch(names)
                next_lookup = time.monotonic() + NAMES_EVERY_S
            mirror.wait_and_forward(0.2)
    finally:
        if controls is not None:
            controls.close()
        if mirror is not None:
            mirror.close()
        queryable.undeclare()


def _worker_names(sock: Path) -> list[str]:
    """The run's components (the workers of the supervision tree); none if it does not answer."""
    from emos.core.rpc import RpcClient

    try:
        with RpcClient(sock, timeout=5.0) as rpc:
            tree = rpc.call("tree")["tree"]
    except Exception as exc:  # noqa: BLE001 - starting or stopping: try again later
        log.debug("zenoh status helper: the supervisor's tree: %s", exc)
        return []
    names, todo = [], [tree]
    while todo:
        node = todo.pop()
        if node.get("kind") == "worker" and node.get("name"):
            names.append(str(node["name"]))
        todo.extend(node.get("children", []))
    return names


def main(argv: list[str]) -> int:
    import signal

    from emos.core.prctl import die_with

    run_dir, run_id, parent = Path(argv[0]), argv[1], int(argv[2])
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the group; the supervisor stops us
    if not die_with(parent, signal.SIGTERM):
        return 0
    logging.basicConfig(level=logging.WARNING, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    try:
        _serve(run_dir, run_id)
    finally:
        from emos.transport.zenoh_net import close_sessions

        close_sessions()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
