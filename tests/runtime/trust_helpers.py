"""A second local user who attacks our runs, and rings forged the way such a user (or a crashed
writer) would leave them. Everything planted is removed in teardown, even when a test fails."""
from __future__ import annotations

import os
import secrets
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np
import pytest

from emos.msgs import codec
from emos.msgs.registry import canonical_name
from emos.transport import ring as R
from emos.transport.context import SHM_DIR, RunContext


class Attacker:
    """Runs commands as another, unprivileged local user (through ``runuser``)."""

    def __init__(self, name: str):
        self.name = name
        out = subprocess.run(["id", "-u", name], capture_output=True, text=True, check=True)
        self.uid = int(out.stdout)
        self.planted: list[Path] = []

    def run(self, *cmd: str, data: bytes | None = None) -> subprocess.CompletedProcess:
        result = subprocess.run(["runuser", "-u", self.name, "--", *cmd], input=data, capture_output=True, timeout=30)
        if result.returncode != 0:
            raise AssertionError(f"as {self.name}: {cmd} failed: {result.stderr.decode(errors='replace')}")
        return result

    def plant_file(self, path: Path, data: bytes, mode: int = 0o666) -> Path:
        self.planted.append(path)
        self.run("sh", "-c", f'cat > "$1" && chmod {mode:o} "$1"', "sh", str(path), data=data)
        return path

    def plant_dir(self, path: Path) -> Path:
        self.planted.append(path)
        self.run("mkdir", str(path))
        return path

    def plant_symlink(self, path: Path, target: Path) -> Path:
        self.planted.append(path)
        self.run("ln", "-s", str(target), str(path))
        return path

    def remove_planted(self) -> None:
        for path in reversed(self.planted):
            try:
                if path.is_dir() and not path.is_symlink():
                    shutil.rmtree(path)
                else:
                    path.unlink()
            except FileNotFoundError:
                pass
        self.planted.clear()


# The fixtures carry their names in name=, so a test module that imports them (to register them)
# binds other names than its tests' parameters (no redefinition of an imported name).
@pytest.fixture(scope="module", name="attacker")
def attacker_fixture():
    """A fresh unprivileged user for this module, removed (with its home) afterwards."""
    if os.geteuid() != 0 or shutil.which("useradd") is None or shutil.which("runuser") is None:
        pytest.skip("creating a second local user needs root, useradd and runuser")
    name = f"emost9a{secrets.token_hex(3)}"
    made = subprocess.run(["useradd", "--create-home", "--shell", "/bin/sh", name], capture_output=True, text=True)
    if made.returncode != 0:
        pytest.skip(f"cannot create a second local user: {made.stderr.strip()}")
    who = Attacker(name)
    try:
        yield who
    finally:
        who.remove_planted()
        subprocess.run(["userdel", "-r", name], capture_output=True)


@pytest.fixture(name="planted")
def planted_fixture(attacker):
    """The attacker, with whatever a test plants removed after it, pass or fail."""
    try:
        yield attacker
    finally:
        attacker.remove_planted()


@pytest.fixture(name="shared_tmp")
def shared_tmp_fixture():
    """A world-writable sticky directory like /tmp or /dev/shm, private to one test."""
    path = Path(tempfile.mkdtemp(prefix="t9a-trust-"))
    os.chmod(path, 0o1777)
    try:
        yield path
    finally:
        shutil.rmtree(path, ignore_errors=True)


def forged_ring(ctx: RunContext, msg_cls: type, messages: list, bad_slot: bool = False, depth: int = 4) -> bytes:
    """The bytes of a well-formed ring of ``msg_cls`` holding ``messages``; with ``bad_slot`` the
    message map sends every message to slot 0xFFFF (far outside the segment)."""
    name = f"{ctx.shm_prefix}forge~{secrets.token_hex(4)}.x.g0"
    ring = R.Ring.create(name, depth, 4096, msg_cls._emos_fingerprint, canonical_name(msg_cls))
    try:
        for msg in messages:
            ring.write(codec.pack(msg))
        if bad_slot:
            for n in range(ring.first, ring.head):
                ring.q[R._MAP_IDX + n % ring.depth] = (n << 16) | 0xFFFF
        # "Created after any subscriber": a reader that trusts the stamp reads from the start.
        ring.q[R._CREATED] = 1 << 62
        return bytes(ring.mm)
    finally:
        ring.close()
        ring.unlink()


def write_own_file(path: Path, data: bytes, mode: int = 0o600) -> Path:
    """A file of our own uid (as a crashed writer of ours would leave one)."""
    fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, mode)
    try:
        os.write(fd, data)
        os.fchmod(fd, mode)
    finally:
        os.close(fd)
    return path


def publish_bad_message(path: Path) -> None:
    """Append one message whose map entry points at slot 0xFFFF to the ring file at ``path``
    (what a writer scribbling on its own ring, or one that dies mid-way, can leave)."""
    q = np.memmap(path, dtype=np.uint64, mode="r+")
    try:
        depth, n = int(q[R._GEOM]) & 0xFFFFFFFF, int(q[R._HEAD])
        q[R._MAP_IDX + n % depth] = (n << 16) | 0xFFFF
        q[R._HEAD] = n + 1
        q.flush()
    finally:
        del q


__all__ = ["Attacker", "attacker_fixture", "planted_fixture", "shared_tmp_fixture", "forged_ring", "publish_bad_message", "write_own_file", "SHM_DIR"]
