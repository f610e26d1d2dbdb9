"""Issue 41 item 2, the UI's certificate from each source, served for real: an identity of the
EMOS keystore (`emos security`, clients trust the keystore's CA), the user's own files, and
refusals that name the files. A UIServer in this process, on its component's loop (uvloop)."""
from __future__ import annotations

import asyncio
import ssl
from pathlib import Path

import aiohttp
import pytest

from tests.ui.conftest import free_port

pytestmark = [pytest.mark.process, pytest.mark.timeout(120)]


def _serve_and_get(config, ca: Path, path: str = "/api/v1/session") -> tuple[int, dict]:
    """Start a UIServer with ``config``, GET ``path`` trusting only ``ca``; (status, JSON)."""
    from emos.actors.ui.server import UIServer

    server = UIServer(config, [], {"/q": "String"}, {}, publish=lambda topic, msg: None, control_socket=lambda name: Path(name),
                      supervisor_socket=None, own_name="ui")

    async def scenario() -> tuple[int, dict]:
        server.bind()
        await server.start()
        try:
            ctx = ssl.create_default_context(cafile=str(ca))
            async with aiohttp.ClientSession(connector=aiohttp.TCPConnector(ssl=ctx)) as s, \
                    s.get(f"https://127.0.0.1:{config.port}{path}", headers={"Authorization": f"Bearer {config.token}"}) as r:
                return r.status, await r.json()
        finally:
            await server.stop()

    import uvloop

    return uvloop.run(scenario())


def test_the_keystore_identity_serves_https_trusted_through_the_ca(tmp_path):
    keystore = pytest.importorskip("emos.security.keystore")
    from emos.actors.ui.config import UIConfig
    from emos.actors.ui.launch import prepare_certificate

    ks = tmp_path / "keystore"
    keystore.create_keystore(ks)
    keystore.create_identity(ks, "ui", hosts=["127.0.0.1", "localhost"])
    config = UIConfig(port=free_port(), token="t0ken-for-this-test", tls="on", keystore=str(ks), pairing=False)
    origin = prepare_certificate(config)
    assert f"certificate of 'ui' from the keystore {ks}" in origin and "SHA-256" in origin
    status, body = _serve_and_get(config, keystore.ca_certificate_path(ks))
    assert status == 200 and body["role"] == "operator"
    # An identity the keystore does not have: a clear error naming it.
    with pytest.raises(Exception, match="has no identity 'dashboard'"):
        prepare_certificate(UIConfig(port=free_port(), token="x" * 20, tls="on", keystore=str(ks), identity="dashboard"))


def test_the_users_own_certificate_and_a_key_that_does_not_fit(tmp_path):
    from emos.actors.ui import tls
    from emos.actors.ui.config import UIConfig
    from emos.actors.ui.launch import prepare_certificate
    from emos.errors import ConfigError

    cert, key = tls.self_signed(["127.0.0.1", "localhost"], tmp_path / "mine")
    config = UIConfig(port=free_port(), token="t0ken-for-this-test", tls="on", certfile=str(cert), keyfile=str(key), pairing=False)
    assert prepare_certificate(config).startswith(f"certificate {cert}")
    status, _ = _serve_and_get(config, cert)
    assert status == 200
    other_cert, other_key = tls.self_signed(["127.0.0.1"], tmp_path / "other")
    assert tls.self_signed(["127.0.0.1"], tmp_path / "other") == (other_cert, other_key)  # reused while it fits
    bad = UIConfig(port=free_port(), token="t0ken-for-this-test", tls="on", certfile=str(cert), keyfile=str(other_key))
    with pytest.raises(ConfigError, match=f"the UI's certificate {cert} with key {other_key} cannot be used"):
        prepare_certificate(bad)


def test_a_ui_off_loopback_without_tls_does_not_start(tmp_path):
    from emos.actors.ui.config import UIConfig
    from emos.actors.ui.server import UIServer

    config = UIConfig(port=free_port(), host="0.0.0.0", token="t0ken-for-this-test", tls="off")
    server = UIServer(config, [], {}, {}, publish=lambda t, m: None, control_socket=lambda n: Path(n), supervisor_socket=None, own_name="ui")
    with pytest.raises(ValueError, match="would send its tokens across the network in clear"):
        asyncio.run(_start(server))


async def _start(server) -> None:
    server.bind()
    try:
        await server.start()
    finally:
        await server.stop()
