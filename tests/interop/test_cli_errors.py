"""Bad input to `emos record`, `emos play` and `emos viz` is refused with a message naming it."""
from __future__ import annotations

import subprocess
import sys

import pytest

pytestmark = pytest.mark.process


def emos(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "emos", *args], capture_output=True, text=True, timeout=60)


@pytest.mark.parametrize("args, message", [
    (["record", "-o", "{existing}"], "exists (use --force to overwrite)"),
    (["record", "-o", "{new}", "--nice", "30"], "--nice must be 0..19"),
    (["record", "-o", "{new}", "--duration", "0"], "--duration must be > 0"),
    (["record", "-o", "{new}", "--defer-ms", "-1"], "--defer-ms must be 0..1000"),
    (["play", "{missing}"], "no such file"),
    (["play", "{existing}", "--rate", "0"], "--rate must be > 0"),
    (["viz", "--port", "70000"], "--port must be 0..65535"),
    (["viz", "--distribution", "rolling"], "--distribution must be one of humble"),
    (["play", "{existing}", "--distribution", "noetic"], "--distribution must be one of humble"),
    (["record", "-o", "{new}", "--import", "no_such_module_xyz"], "cannot import 'no_such_module_xyz'"),
])
def test_bad_arguments(tmp_path, args, message):
    existing = tmp_path / "old.mcap"
    existing.write_bytes(b"")
    paths = {"existing": str(existing), "new": str(tmp_path / "new.mcap"), "missing": str(tmp_path / "missing.mcap")}
    out = emos(*[a.format(**paths) for a in args])
    assert out.returncode != 0
    assert message in out.stderr, out.stderr
    assert not (tmp_path / "new.mcap").exists()


def test_commands_are_listed_in_help():
    out = emos("--help")
    for word in ("record", "play", "viz"):
        assert word in out.stdout
