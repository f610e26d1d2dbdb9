"""The one place where EMOS builds the configuration of a Zenoh session, and opens it.

Two cases:

* **A configuration file** (``emos run --zenoh CONFIG``, ``$EMOS_ZENOH_CONFIG``,
  ``use_network(zenoh_config=...)``, ``--remote CONFIG``): taken as written, except that Zenoh's
  own shared memory is turned off unless the file mentions ``shared_memory`` (see
  :func:`load_config`). Reaching other hosts always takes such a file.
* **No file**: loopback only. The session listens on ``tcp/127.0.0.1:<port>`` and nowhere else,
  with no multicast or gossip scouting, so nothing of it can be reached from another host and
  it sends nothing to the LAN. (Zenoh's own defaults listen on every interface and scout by
  multicast on every multicast interface, with no authentication: any host of the LAN could
  read and publish the robot's topics.) Sessions of one host still find each other: each
  registers its endpoint in a directory only our user can open (``zenoh-peers/`` under the EMOS
  runtime directory, see :func:`emos.transport.context.runtime_root`) and connects to every
  live one registered before it, holding a lock from the listing to the registration, so that
  of two sessions that start together the second always sees the first (a full mesh).

  Why not Zenoh's multicast scouting bound to ``lo`` (``scouting/multicast/interface: "lo"``)?
  It does find peers on this host (measured with eclipse-zenoh 1.10.2), but Zenoh still binds
  its unicast scouting socket to ``0.0.0.0`` (measured) and connects to the locators of any
  Hello that socket receives (its scouting code), so a host of the LAN could make the session
  connect out to it; and its socket on ``224.0.0.224:7446`` also receives the LAN's scouts as
  soon as another process of the host joins that group on a LAN interface. A registration
  directory needs no UDP socket at all.

Whatever the case, a configuration whose sessions can be reached from, or reach, another host
(a listen or connect endpoint that is not loopback, or multicast scouting on an interface that
is not) is logged once per process as a WARNING naming those addresses: anyone who reaches them
reads and writes the group's topics. See docs/network.md, "Security".
"""
from __future__ import annotations

import atexit
import fcntl
import ipaddress
import json
import logging
import os
import re
import socket
import stat
import threading
import time
from pathlib import Path
from typing import Any, Self

from emos.hosts import is_loopback

log = logging.getLogger("emos.transport.zenoh")
ENV_ZENOH_CONFIG = "EMOS_ZENOH_CONFIG"
LOOPBACK_HOST = "127.0.0.1"
PEERS_SUBDIR = "zenoh-peers"  # under runtime_root(); not a run id, so no sweep of run dirs touches it
_ENTRY_RE = re.compile(r"^(\d+)-(\d+)\.json$")
_ENDPOINT_RE = re.compile(r"^tcp/127\.0\.0\.1:(\d{1,5})$")  # all a registered endpoint may be
_LOCK_WAIT_S = 10.0  # bounds a wait on a peer stuck inside its open; then we go on without the lock
_LOCAL_LINKS = ("unixsock-stream", "unixpipe")  # endpoints that are files of this host
_DEFAULT_MULTICAST = "224.0.0.224:7446"  # Zenoh's, when the configuration names none


# ------------------------------------------------------------------------------------ files
def load_config(zenoh: Any, path: str) -> Any:
    """The configuration in ``path``, with Zenoh's own shared memory turned off unless the file
    says anything about ``shared_memory``.

    Why off: Zenoh 1.10 moves messages of 3 KiB or more between processes of one host through
    shared-memory pools it maps into the receivers, and a receiver keeps the pool (16 MiB) and
    metadata (1.3 MB) of every sending process it ever heard mapped and locked for its own
    lifetime, a clean exit or a SIGKILL of the sender alike (eclipse-zenoh/zenoh#2787, open).
    A component restarted by its supervisor is a new sending process each time, so subscribers
    would grow by 17 MB per restart. Processes of one host already have EMOS's own rings, which
    free a dead writer's segments; Zenoh is for crossing hosts, where its shared memory does not
    apply. A configuration file that mentions ``shared_memory`` is taken as it is.

    An empty ``path`` is the loopback-only default (:func:`loopback_config`, with no peers)."""
    if not path:
        return loopback_config(zenoh, 0, [])
    if not os.path.isfile(path):
        raise FileNotFoundError(f"Zenoh configuration file {path!r} (from --zenoh or ${ENV_ZENOH_CONFIG}) does not exist")
    try:
        conf = zenoh.Config.from_file(path)
    except Exception as exc:  # noqa: BLE001 - zenoh.ZError: say which file
        raise ValueError(f"Zenoh configuration file {path!r} is invalid: {exc}") from None
    if os.environ.get("EMOS_ZENOH_SECURE") == "1":  # emos run --secure / use_secure(): never a plain file
        from emos.security.secure_run import check_secure

        check_secure(conf, repr(path))
    with open(path, encoding="utf-8", errors="replace") as f:
        if "shared_memory" in f.read():
            return conf
    conf.insert_json5("transport/shared_memory/enabled", "false")
    return conf


def loopback_config(zenoh: Any, port: int, peers: list[str]) -> Any:
    """EMOS's configuration when there is no file: a peer that listens on ``127.0.0.1:port``
    only, connects to ``peers`` (loopback endpoints of this user's other sessions), and scouts
    neither by multicast nor by gossip (gossip would pass on the endpoints other peers know,
    which need not be loopback)."""
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("listen/endpoints", json.dumps([f"tcp/{LOOPBACK_HOST}:{int(port)}"]))
    conf.insert_json5("connect/endpoints", json.dumps(peers))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("scouting/gossip/enabled", "false")
    # A peer that exits is never back at the same endpoint (a new session registers anew), so
    # retrying its endpoint is useless: at most once a minute rather than Zenoh's 4 s.
    conf.insert_json5("connect/retry", '{"period_init_ms": 1000, "period_max_ms": 60000, "period_increase_factor": 2}')
    conf.insert_json5("transport/shared_memory/enabled", "false")  # see load_config
    return conf


# ------------------------------------------------------------------------------------ exposure
def _json(conf: Any, key: str) -> Any:
    try:
        return json.loads(conf.get_json(key))
    except Exception:  # noqa: BLE001 - a key this Zenoh version does not know: not set
        return None


def _for_mode(value: Any, mode: str) -> list[str]:
    """A mode-dependent endpoint list (a list, or ``{"router": [...], "peer": [...], ...}``)."""
    if isinstance(value, dict):
        value = value.get(mode)
    return [str(v) for v in value] if isinstance(value, list) else []


def is_loopback_endpoint(endpoint: str) -> bool:
    """Whether a Zenoh endpoint (``proto/address[?params][#config]``) stays on this host: an
    address of 127.0.0.0/8 or ::1, ``localhost``, or a Unix socket. A host name, ``0.0.0.0`` or
    ``[::]`` (every interface) is not."""
    proto, _, rest = str(endpoint).partition("/")
    if proto in _LOCAL_LINKS:
        return True
    address = re.split(r"[?#]", rest, maxsplit=1)[0]
    host = address.rsplit(":", 1)[0] if ":" in address else address
    return is_loopback(host)


def _is_loopback_interface(name: str) -> bool:
    name = name.strip()
    if name in ("lo", "lo0"):
        return True
    try:
        return ipaddress.ip_address(name).is_loopback
    except ValueError:
        return False  # "auto" (every multicast interface) or another interface's name


def exposure(conf: Any) -> list[str]:
    """What in ``conf`` reaches beyond this host: ``["listen tcp/0.0.0.0:7447", ...]``, empty if
    nothing does. Unset keys count as Zenoh's defaults (peer mode, listening on ``[::]``,
    multicast scouting on every multicast interface)."""
    mode = _json(conf, "mode") or "peer"
    listen = _for_mode(_json(conf, "listen/endpoints"), mode)
    connect = _for_mode(_json(conf, "connect/endpoints"), mode)
    found = [f"listen {e}" for e in listen if not is_loopback_endpoint(e)]
    found += [f"connect {e}" for e in connect if not is_loopback_endpoint(e)]
    multicast = _json(conf, "scouting/multicast/enabled")
    scouts = multicast is not False and not (mode == "client" and connect)  # a client with endpoints does not scout
    if scouts:
        interface = str(_json(conf, "scouting/multicast/interface") or "auto")
        if not all(_is_loopback_interface(i) for i in interface.split(",")):
            group = _json(conf, "scouting/multicast/address") or _DEFAULT_MULTICAST
            found.append(f"multicast scouting on interface {interface} ({group})")
    return found


_warned: set[int] = set()  # pids that have warned (a forked child warns for itself)
_warned_lock = threading.Lock()


def warn_if_exposed(conf: Any, source: str) -> list[str]:
    """Log, once per process, a WARNING naming what of ``conf`` (from ``source``) reaches beyond
    this host; returns those addresses (empty: loopback only)."""
    found = exposure(conf)
    if not found:
        return found
    with _warned_lock:
        if os.getpid() in _warned:
            return found
        _warned.add(os.getpid())
    tls, acl = _json(conf, "transport/link/tls") or {}, _json(conf, "access_control") or {}
    if tls.get("enable_mtls") is True and acl.get("enabled") is True and _json(conf, "transport/link/protocols") == ["tls"]:
        # emos security policy's kind of file: peers need a certificate of its CA, and the rules say what each may do
        log.info("Zenoh configuration %s reaches beyond this host (%s) with mutual TLS only and access control on", source, ", ".join(found))
        return found
    log.warning(
        "Zenoh configuration %s reaches beyond this host: %s. EMOS topics (and the services and control "
        "a run shares over Zenoh) are readable and writable by anyone who reaches these addresses: Zenoh "
        "does not authenticate peers unless configured to. Restrict them with TLS/mTLS and access control "
        "in the configuration file (docs/network.md, 'Security'; https://zenoh.io/docs/manual/tls/ and "
        "https://zenoh.io/docs/manual/access-control/)", source, ", ".join(found))
    return found


# ------------------------------------------------------------------------------------ loopback peers
_registered: dict[int, list[Path]] = {}  # pid -> entries it registered (removed at close or exit)
_registered_lock = threading.Lock()
_atexit_registered = False


def peers_dir() -> Path:
    """The directory where this user's loopback sessions register (created 0700)."""
    from emos.transport.context import runtime_root

    root = runtime_root()  # ours, 0700, checked: nobody else can plant entries under it
    folder = root / PEERS_SUBDIR
    try:
        folder.mkdir(mode=0o700, exist_ok=True)
    except FileExistsError:
        pass
    st = os.lstat(folder)
    if not stat.S_ISDIR(st.st_mode) or st.st_uid != os.geteuid():
        raise PermissionError(f"{folder} (where EMOS's loopback Zenoh sessions register) is not a directory of ours; remove it")
    return folder


def _live_peers(folder: Path) -> list[str]:
    """The endpoints of the live sessions registered in ``folder``, other than this process's;
    entries of dead processes (or of a reused pid) are removed."""
    from emos.transport.context import _start_token

    peers = []
    for entry in sorted(folder.iterdir()):
        m = _ENTRY_RE.match(entry.name)
        if m is None:
            continue  # the lock, a half-written entry
        pid = int(m.group(1))
        if pid == os.getpid():
            continue
        try:
            data = json.loads(entry.read_text())
            endpoint, token = str(data["endpoint"]), int(data["token"])
        except (OSError, ValueError, KeyError, TypeError):
            continue  # unreadable: not ours to judge, and never connected to
        if _start_token(pid) != token:
            entry.unlink(missing_ok=True)  # that process is gone (its session was never closed)
            continue
        if _ENDPOINT_RE.match(endpoint):  # a loopback TCP endpoint, whatever the file says
            peers.append(endpoint)
    return peers


class _PeersLock:
    """An exclusive lock on ``folder/.lock``, waited for at most ``_LOCK_WAIT_S`` (a session
    stuck in its open must not stop every other): after that we go on unlocked, and at worst
    two sessions that opened at that very moment do not connect to each other."""

    def __init__(self, folder: Path):
        self.path = folder / ".lock"
        self.fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC | os.O_NOFOLLOW, 0o600)
        self.locked = False

    def __enter__(self) -> Self:
        deadline = time.monotonic() + _LOCK_WAIT_S
        while True:
            try:
                fcntl.flock(self.fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                self.locked = True
                return self
            except BlockingIOError:
                if time.monotonic() > deadline:
                    log.warning("Zenoh: %s was held for over %.0f s; opening this session without it", self.path, _LOCK_WAIT_S)
                    return self
                time.sleep(0.01)

    def __exit__(self, *exc: object) -> None:
        os.close(self.fd)  # releases the lock


def _free_loopback_port() -> int:
    with socket.socket() as s:
        s.bind((LOOPBACK_HOST, 0))
        port: int = s.getsockname()[1]
        return port


def open_loopback(zenoh: Any) -> tuple[Any, Path]:
    """Open a loopback-only session that connects to this user's other loopback sessions on
    this host, and register it for the ones that open later: ``(session, registration)``
    (:func:`unregister` the registration when the session closes)."""
    from emos.transport.context import _start_token

    folder = peers_dir()
    with _PeersLock(folder):
        peers = _live_peers(folder)
        for attempt in range(5):
            # Zenoh cannot tell us the port it picked for ":0", so we pick it; another process
            # may take it between our close and Zenoh's bind: then another.
            port = _free_loopback_port()
            conf = loopback_config(zenoh, port, peers)
            warn_if_exposed(conf, "EMOS's default (no configuration file)")  # never, unless loopback_config changes
            try:
                sess = zenoh.open(conf)
                break
            except Exception as exc:  # zenoh.ZError; anything else is raised again
                if "Address already in use" not in str(exc) or attempt == 4:
                    raise
        endpoint = f"tcp/{LOOPBACK_HOST}:{port}"
        entry = folder / f"{os.getpid()}-{port}.json"
        tmp = folder / f".{entry.name}.tmp"
        try:
            tmp.write_text(json.dumps({"pid": os.getpid(), "token": _start_token(os.getpid()), "endpoint": endpoint}))
            os.replace(tmp, entry)
        except OSError as exc:
            sess.close()  # a session nobody can find would look fine and hear nothing
            tmp.unlink(missing_ok=True)
            raise OSError(exc.errno, f"Zenoh: cannot register this process's loopback session in {folder}: {exc.strerror}") from None
    global _atexit_registered
    with _registered_lock:
        if not _atexit_registered:
            atexit.register(unregister_all)
            _atexit_registered = True
        _registered.setdefault(os.getpid(), []).append(entry)
    log.info("Zenoh session %s opened on loopback only (%s; %d other EMOS session(s) of this user on this host); "
             "other hosts need a configuration file (emos run --zenoh CONFIG)", sess.info.zid(), endpoint, len(peers))
    return sess, entry


def unregister(entry: Path) -> None:
    """Remove one registration of this process (its session was closed): a later session must
    not wait on an endpoint that no longer answers."""
    with _registered_lock:
        mine = _registered.get(os.getpid(), [])
        if entry not in mine:
            return
        mine.remove(entry)
    entry.unlink(missing_ok=True)


def unregister_all() -> None:
    """Remove this process's registrations (its sessions are closing, or it exits)."""
    with _registered_lock:
        entries = _registered.pop(os.getpid(), [])
    for entry in entries:
        try:
            entry.unlink(missing_ok=True)
        except OSError as exc:  # the runtime directory is gone already: nothing to remove
            log.debug("Zenoh: removing %s: %s", entry, exc)
