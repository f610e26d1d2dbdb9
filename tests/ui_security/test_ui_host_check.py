"""DNS rebinding off loopback: a UI bound to every address answered any ``Host`` (the check held
on loopback only), so a page of attacker.example that rebinds its name to the robot's address
could read it with the victim's cookie. Now the Host must be a name of this machine."""
from __future__ import annotations

import asyncio

import pytest
from aiohttp import web
from aiohttp.test_utils import TestClient, TestServer

from emos.actors.ui.auth import make_middleware

pytestmark = pytest.mark.process


def test_off_loopback_only_this_machines_names_are_served():
    async def hello(request: web.Request) -> web.Response:
        return web.Response(text="hello")

    app = web.Application(middlewares=[make_middleware("0.0.0.0", "s3cret", 5001)])
    app.router.add_get("/", hello)

    async def scenario() -> None:
        async with TestClient(TestServer(app)) as client:
            ok = {"Authorization": "Bearer s3cret"}
            for host in ("attacker.example", "attacker.example:5001", "robot.evil.example:5001"):
                r = await client.get("/", headers={**ok, "Host": host})
                assert r.status == 403, (host, r.status, await r.text())
            assert (await client.get("/", headers={**ok, "Host": "127.0.0.1:5001"})).status == 200
            assert (await client.get("/", headers=ok)).status == 200

    asyncio.run(scenario())
