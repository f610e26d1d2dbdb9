"""A secured UI recipe (HTTPS with a self-signed certificate made by the run, pairing on) under
`emos run`, and clients that verify its certificate for real."""
from __future__ import annotations

import asyncio
import json
import os
import re
import ssl
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, NamedTuple

import aiohttp
import pytest

from tests.ui.conftest import free_port, stop_recipe, token_of, wait_http

HERE = Path(__file__).parent
ROOT = HERE.parent.parent
LINK_RE = re.compile(r"EMOS UI: (https?://\S+)")
CODE_RE = re.compile(r"enter the code ([0-9A-Z]{4}-[0-9A-Z]{4})")
CERT_RE = re.compile(r"self-signed certificate (\S+), SHA-256 ([0-9A-F:]+)")


class Secured(NamedTuple):
    port: int
    out: Path
    proc: subprocess.Popen
    link: str
    log: Path
    cert: Path | None
    fingerprint: str
    code: str
    home: Path

    @property
    def token(self) -> str:
        return token_of(self.link)

    @property
    def base(self) -> str:
        return self.link.split("/?", 1)[0]

    def log_text(self) -> str:
        return self.log.read_text()

    def received(self) -> list[dict[str, Any]]:
        try:
            return [json.loads(line) for line in self.out.read_text().splitlines() if line.strip()]
        except FileNotFoundError:
            return []


def _wait_for(log: Path, proc: subprocess.Popen, pattern: re.Pattern[str], timeout: float = 60.0) -> re.Match[str]:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        m = pattern.search(log.read_text()) if log.exists() else None
        if m:
            return m
        if proc.poll() is not None:
            raise RuntimeError(f"the recipe exited with code {proc.returncode}: {log.read_text()[-3000:]}")
        time.sleep(0.2)
    raise TimeoutError(f"no {pattern.pattern!r} in {log} after {timeout} s: {log.read_text()[-2000:]}")


def run_secured(tmp: Path, https: bool = True, headless: bool = False, extra_flags: tuple[str, ...] = (), extra_env: dict[str, str] | None = None):
    port, out, home = free_port(), tmp / "received.jsonl", tmp / "home"
    env = dict(os.environ, EMOS_UI_TEST_PORT=str(port), EMOS_UI_TEST_OUT=str(out), EMOS_HOME=str(home),
               EMOS_UI_TEST_HEADLESS="1" if headless else "0", **(extra_env or {}))
    env.pop("EMOS_UI_TOKEN", None)
    log = tmp / "recipe.log"
    flags = (["--ui-https"] if https else []) + list(extra_flags)
    with open(log, "w") as f:
        proc = subprocess.Popen([sys.executable, "-m", "emos.tools.cli", "run", *flags, str(HERE / "secure_recipe.py")], env=env,
                                stdout=f, stderr=subprocess.STDOUT, start_new_session=True, cwd=ROOT)
    try:
        link = _wait_for(log, proc, LINK_RE).group(1)
        code = _wait_for(log, proc, CODE_RE).group(1)
        cert, fp = None, ""
        if https and not extra_flags:
            m = _wait_for(log, proc, CERT_RE)
            cert, fp = Path(m.group(1)), m.group(2)
        wait_http(port, proc=proc)
        _wait_for(log, proc, re.compile(r"page at https?://"))
        yield Secured(port, out, proc, link, log, cert, fp, code, home)
    finally:
        stop_recipe(proc)
        print(log.read_text()[-4000:])


@pytest.fixture(scope="session")
def secured(tmp_path_factory):
    """One HTTPS system for the folder's tests (per xdist worker): starting one costs seconds."""
    yield from run_secured(tmp_path_factory.mktemp("ui-secured"))


def client_ssl(cert: Path | None) -> ssl.SSLContext | bool:
    """A client context that trusts exactly the UI's certificate (and checks the host name)."""
    if cert is None:
        return False
    ctx = ssl.create_default_context(cafile=str(cert))
    ctx.check_hostname = True
    return ctx


def request(system: Secured, method: str, path: str, headers: dict[str, str] | None = None, data: Any = None, json_body: Any = None,
            local_addr: str | None = None) -> tuple[int, Any, dict[str, str]]:
    """One request without a cookie jar: (status, JSON or text body, response headers)."""
    async def go() -> tuple[int, Any, dict[str, str]]:
        conn = aiohttp.TCPConnector(ssl=client_ssl(system.cert), local_addr=(local_addr, 0) if local_addr else None)
        async with aiohttp.ClientSession(connector=conn, cookie_jar=aiohttp.DummyCookieJar()) as s, \
                s.request(method, system.base + path, headers=headers or {}, data=data, json=json_body, allow_redirects=False) as r:
            text = await r.text()
            try:
                body: Any = json.loads(text)
            except ValueError:
                body = text
            return r.status, body, dict(r.headers)
    return asyncio.run(go())


def bearer(token: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}"}


def pair(system: Secured, code: str, role: str = "operator", name: str = "tablet") -> tuple[int, Any]:
    status, body, _ = request(system, "POST", "/api/pair", json_body={"code": code, "name": name, "role": role})
    return status, body


def next_code(system: Secured, cli: bool = False) -> str:
    """The current pairing code: as `emos ui pair` shows it (``cli``), or read from the file
    that command reads (``<run dir>/ui.pairing``; faster: no CLI start-up)."""
    if cli:
        out = emos(system, "ui", "pair")
        m = re.search(r"pairing code ([0-9A-Z]{4}-[0-9A-Z]{4})", out.stdout)
        assert m, out.stdout + out.stderr
        return m.group(1)
    from emos.transport.context import runtime_root

    return str(json.loads((runtime_root() / run_id_of(system) / "ui.pairing").read_text())["code"])


def emos(system: Secured, *words: str) -> subprocess.CompletedProcess[str]:
    run_id = run_id_of(system)
    env = dict(os.environ, EMOS_HOME=str(system.home))
    cmd = [sys.executable, "-m", "emos.tools.cli", *words[:2], "--run", run_id, *words[2:]]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=60, env=env, cwd=ROOT)


def run_id_of(system: Secured) -> str:
    m = re.search(r"system up: .*\(run (\S+)\)", system.log_text())
    if m:
        return m.group(1)
    status, body, _ = request(system, "GET", "/api/v1/system", bearer(system.token))
    assert status == 200, body
    return str(body["run_id"])


def paired_operator(system: Secured, role: str = "operator", name: str = "tablet") -> str:
    status, body = pair(system, next_code(system), role=role, name=name)
    assert status == 200 and body["ok"], body
    return str(body["token"])
