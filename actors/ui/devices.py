"""Device tokens: what a paired tablet or a fleet manager signs in with.

A device token is ``emosd_<id>.<secret>``: the id finds the record, the secret proves it. Only
SHA-256 of the secret is stored (the secret is 32 random bytes, so a plain hash is enough: there
is nothing to brute-force, unlike a password), next to the device's name, role and expiry. The
store is one JSON file of ours (mode 0600 in a 0700 directory, replaced atomically), by default
``<run dir>/ui.devices.json``; ``emos ui tokens`` lists it (:meth:`DeviceStore.listing`) and ``emos ui revoke`` edits it, and
the UI rereads it when its modification time changes, so a revocation holds at the next request
(open websockets of the device are closed within a second).

Read-modify-write is serialized between the UI and the CLI with ``flock`` on ``<store>.lock``.
"""
from __future__ import annotations

import contextlib
import fcntl
import hashlib
import hmac
import json
import logging
import os
import re
import secrets
import stat
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from emos.actors.ui.tokenfile import FILE_MODE, directory_problem, write_private_file
from emos.errors import EmosError

log = logging.getLogger("emos.ui")

ROLES = ("viewer", "operator")
PREFIX = "emosd_"
STORE_NAME = "ui.devices.json"
_TOKEN_RE = re.compile(r"^emosd_([0-9a-f]{12})\.([A-Za-z0-9_-]{20,64})$")
_NAME_RE = re.compile(r"^[\w .@:+-]{1,64}$")
KEEP_DEAD_S = 86400.0  # revoked and expired records are kept a day (so a refusal can say why), then dropped


class DeviceStoreError(EmosError, ValueError):
    """The device-token store cannot be used (the path and the reason are in the message)."""


def check_role(role: Any, where: str = "role") -> str:
    if role not in ROLES:
        raise ValueError(f"{where} must be one of {', '.join(ROLES)}, got {role!r}")
    return str(role)


def _digest(secret: str) -> str:
    return hashlib.sha256(secret.encode()).hexdigest()


class DeviceStore:
    def __init__(self, path: Path, clock: Any = time.time):
        self.path = Path(path)
        self.lock_path = self.path.with_name(self.path.name + ".lock")
        self.clock = clock
        self._cache: tuple[tuple[int, int, int], dict[str, dict[str, Any]]] | None = None

    # ------------------------------------------------------------------ file
    def _read(self) -> dict[str, dict[str, Any]]:
        """The records by id; an absent store is empty. A store that is not ours (owner, mode,
        a link) is refused: its records would be someone else's tokens."""
        try:
            fd = os.open(self.path, os.O_RDONLY | os.O_NOFOLLOW | os.O_CLOEXEC)
        except FileNotFoundError:
            return {}
        except OSError as exc:
            raise DeviceStoreError(f"device-token store {self.path}: cannot be opened ({exc.strerror})") from None
        try:
            st = os.fstat(fd)
            if not stat.S_ISREG(st.st_mode) or st.st_uid != os.geteuid() or stat.S_IMODE(st.st_mode) != FILE_MODE:
                raise DeviceStoreError(f"device-token store {self.path}: not a file of ours with mode 0600 "
                                       f"(uid {st.st_uid}, mode {oct(stat.S_IMODE(st.st_mode))}); not using it")
            key = (st.st_ino, st.st_mtime_ns, st.st_size)
            if self._cache is not None and self._cache[0] == key:
                return self._cache[1]
            raw = os.read(fd, 8 * 2**20)
        finally:
            os.close(fd)
        try:
            data = json.loads(raw or b"{}")
            records = {str(r["id"]): dict(r) for r in data.get("devices", []) if isinstance(r, dict) and "id" in r}
        except (ValueError, TypeError, AttributeError, KeyError) as exc:
            raise DeviceStoreError(f"device-token store {self.path}: not valid ({exc})") from None
        self._cache = (key, records)
        return records

    def _write(self, records: dict[str, dict[str, Any]]) -> None:
        now = self.clock()
        keep = [r for r in records.values()
                if not (r.get("revoked") and float(r["revoked"]) + KEEP_DEAD_S < now) and float(r.get("expires", 0)) + KEEP_DEAD_S > now]
        write_private_file(self.path, json.dumps({"version": 1, "devices": keep}, indent=1) + "\n", "the UI's device-token store")
        self._cache = None

    @contextlib.contextmanager
    def _locked(self) -> Iterator[dict[str, dict[str, Any]]]:
        problem = directory_problem(self.path.parent)
        if problem is not None:
            raise DeviceStoreError(f"device-token store {self.path}: the directory {self.path.parent} {problem} "
                                   "(it must be a directory of ours with mode 0700)")
        fd = os.open(self.lock_path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, FILE_MODE)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)
            self._cache = None
            yield dict(self._read())
        finally:
            os.close(fd)  # releases the lock

    # ------------------------------------------------------------------ API
    def issue(self, name: str, role: str, ttl_s: float, pairing: str = "") -> tuple[str, dict[str, Any]]:
        """A new token for device ``name`` with ``role``, valid ``ttl_s`` seconds: (token, record).
        The token is returned once and never stored. ``pairing``: the digest of the code it paired
        with (pairing.code_digest), so that code never works again."""
        check_role(role)
        if not isinstance(name, str) or not _NAME_RE.match(name):
            raise ValueError(f"device name must be 1-64 letters, digits, spaces or . @ : + - _, got {name!r}")
        if not ttl_s > 0:
            raise ValueError(f"token lifetime must be > 0 s, got {ttl_s!r}")
        secret = secrets.token_urlsafe(32)
        now = self.clock()
        with self._locked() as records:
            device_id = secrets.token_hex(6)
            while device_id in records:
                device_id = secrets.token_hex(6)
            record = {"id": device_id, "name": name, "role": role, "sha256": _digest(secret), "created": now, "expires": now + ttl_s,
                      "revoked": None}
            if pairing:
                record["pairing"] = pairing
            records[device_id] = record
            self._write(records)
        return f"{PREFIX}{device_id}.{secret}", public(record, now)

    def check(self, token: str) -> tuple[dict[str, Any] | None, str]:
        """(the record, "") if ``token`` is a valid device token; else (None, why: a sentence)."""
        m = _TOKEN_RE.match(token or "")
        if m is None:
            return None, "not a device token"
        try:
            record = self._read().get(m.group(1))
        except DeviceStoreError as exc:
            return None, str(exc)
        if record is None or not hmac.compare_digest(str(record.get("sha256", "")), _digest(m.group(2))):
            return None, "unknown device token"
        if record.get("revoked"):
            return None, f"the token of device {record.get('name')!r} ({record['id']}) was revoked"
        if float(record.get("expires", 0)) <= self.clock():
            return None, f"the token of device {record.get('name')!r} ({record['id']}) has expired"
        if record.get("role") not in ROLES:
            return None, f"the token of device {record['id']} has no valid role"
        return record, ""

    def still_valid(self, device_id: str) -> bool:
        try:
            record = self._read().get(device_id)
        except DeviceStoreError:
            return False
        return record is not None and not record.get("revoked") and float(record.get("expires", 0)) > self.clock()

    def records(self) -> list[dict[str, Any]]:
        """Every record as stored (hashes included: for the UI's own checks, never shown)."""
        return [dict(r) for r in self._read().values()]

    def listing(self) -> list[dict[str, Any]]:
        """Every record (without its hash), with a ``status``: active, expired or revoked."""
        return [public(r, self.clock()) for r in sorted(self._read().values(), key=lambda r: r.get("created", 0))]

    def revoke(self, which: str) -> list[dict[str, Any]]:
        """Revoke the device with id ``which``, or every device named ``which``, or ``all``;
        returns the records revoked now (empty: nothing matched or all were revoked already)."""
        now = self.clock()
        with self._locked() as records:
            hit = [r for r in records.values() if not r.get("revoked") and which in ("all", r["id"], r.get("name"))]
            for r in hit:
                r["revoked"] = now
            if hit:
                self._write(records)
        return [public(r, now) for r in hit]


def public(record: dict[str, Any], now: float | None = None) -> dict[str, Any]:
    out = {k: record.get(k) for k in ("id", "name", "role", "created", "expires", "revoked")}
    now = time.time() if now is None else now
    out["status"] = "revoked" if record.get("revoked") else ("expired" if float(record.get("expires", 0)) <= now else "active")
    return out
