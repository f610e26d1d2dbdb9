"""``emos run --secure KEYSTORE`` and its recipe-side twin :func:`use_secure`.

Both pick the identity's Zenoh configuration that ``emos security policy`` wrote
(``KEYSTORE/policies/<recipe>/<identity>.json5``, or a file given explicitly), check that it
really is secure (:func:`check_secure`), and point ``$EMOS_ZENOH_CONFIG`` at it, so that every
Zenoh session of the run (components, the status helper) opens with its TLS, mutual TLS and
access rules: Zenoh does the enforcing. ``$EMOS_ZENOH_SECURE=1`` is set too; with it,
:func:`emos.transport.zenoh_config.load_config` refuses any configuration that fails the check,
so a secure run can never quietly fall back to plain TCP.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

from emos.security.keystore import KeystoreError, _check_keystore, check_name
from emos.security.policy import policy_dir

__all__ = ["ENV_ZENOH_SECURE", "check_secure", "secure_config_path", "use_secure", "start_watch"]

ENV_ZENOH_SECURE = "EMOS_ZENOH_SECURE"


def _get(conf: Any, key: str) -> Any:
    try:
        return json.loads(conf.get_json(key))
    except Exception:  # noqa: BLE001 - a key this Zenoh does not know: unset
        return None


def check_secure(conf: Any, source: str) -> None:
    """Raise :class:`KeystoreError` unless ``conf`` (a ``zenoh.Config``) uses TLS only, with
    mutual TLS, a CA, its own certificate and key, and access control on with ``deny`` by default."""
    problems = []
    tls = _get(conf, "transport/link/tls") or {}
    for key in ("root_ca_certificate", "listen_certificate", "listen_private_key", "connect_certificate", "connect_private_key"):
        if not tls.get(key):
            problems.append(f"transport.link.tls.{key} is not set")
        elif not os.path.isfile(str(tls[key])):
            problems.append(f"transport.link.tls.{key}: {tls[key]} does not exist")
    if tls.get("enable_mtls") is not True:
        problems.append("transport.link.tls.enable_mtls is not true (peers without a certificate could connect)")
    if _get(conf, "transport/link/protocols") != ["tls"]:
        problems.append('transport.link.protocols is not ["tls"] (plain TCP or UDP links would be accepted)')
    mode = _get(conf, "mode") or "peer"
    for side in ("listen", "connect"):
        value = _get(conf, f"{side}/endpoints")
        endpoints = value.get(mode, []) if isinstance(value, dict) else value or []
        bad = [e for e in endpoints if not str(e).startswith("tls/")]
        if bad:
            problems.append(f"{side}.endpoints {bad} are not TLS")
    acl = _get(conf, "access_control") or {}
    if acl.get("enabled") is not True:
        problems.append("access_control.enabled is not true")
    if acl.get("default_permission") != "deny":
        problems.append('access_control.default_permission is not "deny"')
    if _get(conf, "scouting/multicast/enabled") is not False:
        problems.append("scouting.multicast.enabled is not false")
    if problems:
        raise KeystoreError(f"Zenoh configuration {source} is not secure: " + "; ".join(problems))


def secure_config_path(keystore: str | os.PathLike[str], recipe: str | os.PathLike[str] | None, identity: str | None,
                       config: str | os.PathLike[str] | None = None) -> Path:
    """The configuration a secure run of ``recipe`` as ``identity`` uses: ``config`` if given,
    else ``KEYSTORE/policies/<recipe stem>/<identity>.json5`` (``identity`` may be left out when
    the recipe's policy has one robot file only). Checked with :func:`check_secure`."""
    import zenoh

    _check_keystore(keystore)
    if config is not None:
        path = Path(config).expanduser().absolute()
    else:
        if recipe is None:
            raise KeystoreError("a secure run needs the recipe (to find its policy) or an explicit Zenoh configuration file")
        folder = policy_dir(keystore, recipe)
        if identity is None:
            files = sorted(folder.glob("*.json5")) if folder.is_dir() else []
            # a robot's file holds its own policy, "robot <name>" (see emos.security.policy)
            robots = [p for p in files if f'"robot {p.stem}"' in p.read_text(encoding="utf-8", errors="replace")]
            if len(robots) != 1:
                raise KeystoreError(f"no single robot policy in {folder} ({len(robots)} found): run `emos security policy {recipe} "
                                    f"--keystore {keystore} --identity NAME` first, or give --identity NAME")
            path = robots[0]
        else:
            path = folder / f"{check_name(identity)}.json5"
    if not path.is_file():
        raise KeystoreError(f"{path} does not exist: write it with `emos security policy RECIPE --keystore {keystore} --identity NAME`")
    try:
        conf = zenoh.Config.from_file(str(path))
    except Exception as exc:  # noqa: BLE001 - zenoh.ZError: name the file
        raise KeystoreError(f"Zenoh configuration {path} is invalid: {exc}") from None
    check_secure(conf, str(path))
    return path


def use_secure(keystore: str | os.PathLike[str], identity: str | None = None, config: str | os.PathLike[str] | None = None,
               recipe: str | os.PathLike[str] | None = None) -> Path:
    """The recipe's way to ``emos run --secure KEYSTORE [--identity NAME]``: call before
    ``Launcher.bringup()``. ``recipe`` defaults to the running script. Returns the configuration
    used; raises :class:`KeystoreError` (naming the file and the problem) if it is missing or not secure."""
    from emos.transport.zenoh_config import ENV_ZENOH_CONFIG

    if recipe is None and config is None:
        main = sys.modules.get("__main__")
        recipe = getattr(main, "__file__", None) or (sys.argv[0] if sys.argv and sys.argv[0] else None)
    path = secure_config_path(keystore, recipe, identity, config)
    os.environ[ENV_ZENOH_CONFIG] = str(path)
    os.environ[ENV_ZENOH_SECURE] = "1"
    return path


def start_watch(config: str | os.PathLike[str], ready_timeout: float = 60.0) -> subprocess.Popen[bytes]:
    """Start the run's security watch (:mod:`emos.security.watch`) as its own process: exec'd,
    not forked (Zenoh's threads), and dying with its parent. Waits (at most ``ready_timeout``
    s, which only bounds a hang) until its session is open, so that it, not a component, holds
    the configuration's listening port and meets the other hosts' peers directly; a watch that
    does not come up is logged and the run goes on without it."""
    import logging
    import select

    proc = subprocess.Popen([sys.executable, "-m", "emos.security.watch", str(config)], stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, close_fds=True)
    assert proc.stdout is not None
    ready, _, _ = select.select([proc.stdout], [], [], ready_timeout)
    line = proc.stdout.readline() if ready else b""
    if line.strip() != b"ready":
        logging.getLogger("emos.security").warning(
            "security watch (pid %d) did not come up within %.0f s (%s): denied publishers will not be logged; Zenoh's access "
            "control still applies", proc.pid, ready_timeout, "exited" if proc.poll() is not None else "still starting")
    return proc
