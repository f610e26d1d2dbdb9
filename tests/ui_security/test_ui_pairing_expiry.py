"""Issue 41: pairing codes expire on their own (UIConfig.pairing_code_ttl_s, 5 minutes by default),
are single use (also across a restart of the UI), and an expired code is refused with a message
saying when it expired. A real UIServer on a real socket with an injected wall clock: the test
moves the clock and waits on the condition (the code in the pairing file changes), never on time."""
from __future__ import annotations

import asyncio
import json
import re
import time
from pathlib import Path
from typing import Any

import aiohttp
import pytest

from emos.actors.ui.config import UIConfig
from emos.actors.ui.pairing import new_code
from emos.actors.ui.server import UIServer
from tests.ui.conftest import free_port

pytestmark = [pytest.mark.process, pytest.mark.timeout(180)]


class Clock:
    def __init__(self) -> None:
        self.t = time.time()

    def __call__(self) -> float:
        return self.t


def _server(run: Path, config: UIConfig, clock: Clock) -> UIServer:
    return UIServer(config, [], {}, {}, publish=lambda topic, msg: None, control_socket=lambda name: run / f"{name}.ctl",
                    supervisor_socket=None, own_name="ui", token_file=run / "ui.token", devices_file=run / "ui.devices.json",
                    pairing_file=run / "ui.pairing", base_url=f"http://127.0.0.1:{config.port}/", clock=clock)


async def _pair(port: int, code: str) -> tuple[int, dict[str, Any]]:
    async with aiohttp.ClientSession(cookie_jar=aiohttp.DummyCookieJar()) as s, \
            s.post(f"http://127.0.0.1:{port}/api/pair", json={"code": code, "name": "tablet", "role": "viewer"}) as r:
        return r.status, await r.json()


async def _wait_for(predicate: Any, what: str, timeout: float = 30.0) -> Any:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        value = predicate()
        if value:
            return value
        await asyncio.sleep(0.05)
    raise TimeoutError(f"{what}: not within {timeout} s")


def test_a_pairing_code_expires_is_single_use_and_stays_used_across_a_restart(tmp_path):
    run = tmp_path / "run"
    run.mkdir(mode=0o700)
    clock = Clock()
    first = new_code()
    config = UIConfig(port=free_port(), host="127.0.0.1", token="t" * 24, pairing_code=first, pairing_code_ttl_s=300.0,
                      auth_failures_per_minute=2)
    pairing_file = run / "ui.pairing"

    def shown() -> dict[str, Any]:
        try:
            return dict(json.loads(pairing_file.read_text()))
        except (FileNotFoundError, ValueError):
            return {}

    async def scenario() -> None:
        server = _server(run, config, clock)
        server.bind()
        await server.start()
        try:
            # The code in force and when it stops working, as `emos ui pair` reads them.
            assert shown()["code"] == first and shown()["expires"] == pytest.approx(clock.t + 300.0)
            clock.t += 301.0  # five minutes later: nobody used it
            await _wait_for(lambda: shown().get("code") not in (None, first), "a new code after the first expired")
            second = shown()["code"]
            assert shown()["expires"] == pytest.approx(clock.t + 300.0)
            # The expired code: refused, saying so and when; not counted as a guess (the limit is 2).
            for _ in range(3):
                status, body = await _pair(config.port, first)
                assert status == 401 and body["expired"] is True, body
                assert re.search(r"this pairing code expired at \d\d:\d\d:\d\d \(codes are valid 5 min\)", body["error"]), body
                assert "emos ui pair" in body["error"]
            # The new code works once.
            status, body = await _pair(config.port, second)
            assert status == 200 and body["ok"] and body["token"].startswith("emosd_"), body
            status, body = await _pair(config.port, second)
            assert status == 401 and "wrong or used pairing code" in body["error"] and "expired" not in body, body
            third = shown()["code"]
            assert third not in (first, second)
        finally:
            await server.stop()
        assert not pairing_file.exists()
        # A restarted UI process gets the code from its config again: used, so it is replaced.
        config.pairing_code = second
        again = _server(run, config, clock)
        again.bind()
        await again.start()
        try:
            assert shown()["code"] not in (second, "")
            status, body = await _pair(config.port, second)
            assert status == 401, body
        finally:
            await again.stop()

    asyncio.run(scenario())


def test_a_code_that_expired_before_the_ui_came_up_is_replaced_at_once(tmp_path):
    run = tmp_path / "run"
    run.mkdir(mode=0o700)
    clock = Clock()
    printed = new_code()
    # Printed by the launcher 10 s ago with a 5 s lifetime (a slow bringup).
    config = UIConfig(port=free_port(), host="127.0.0.1", token="t" * 24, pairing_code=printed, pairing_code_ttl_s=5.0,
                      pairing_code_expires=clock.t - 5.0)

    async def scenario() -> None:
        server = _server(run, config, clock)
        server.bind()
        await server.start()
        try:
            current = json.loads((run / "ui.pairing").read_text())
            assert current["code"] != printed and current["expires"] == pytest.approx(clock.t + 5.0)
            status, body = await _pair(config.port, printed)
            assert status == 401 and "codes are valid 5 s" in body["error"], body
        finally:
            await server.stop()

    asyncio.run(scenario())


def test_the_lifetime_is_validated():
    for bad in (0, -1, 86401.0):
        with pytest.raises(ValueError, match="pairing_code_ttl_s"):
            UIConfig(pairing_code_ttl_s=bad)
    from emos import Launcher, Topic

    with pytest.raises(ValueError, match="pairing_code_ttl_s"):
        Launcher().enable_ui(outputs=[Topic(name="q", msg_type="String")], pairing_code_ttl_s=0.5)


def test_the_run_prints_until_when_its_code_is_valid(secured):
    """The printed code and its QR code say until when; the pairing file holds that time."""
    line = re.search(r"enter the code (\S+) at /pair \(valid until (\d\d:\d\d:\d\d) \(5 min\), single use; "
                     r"`emos ui pair` shows the current one\)", secured.log_text())
    assert line and line.group(1) == secured.code, secured.log_text()[-3000:]
    if "the QR code above is" in secured.log_text():  # segno installed: the QR code is printed
        assert f"the QR code above is valid until {line.group(2)}" in secured.log_text()
