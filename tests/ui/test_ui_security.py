"""Issue 31 items 1 and 2: who may drive the robot through its web UI.

Real HTTP against a real supervised system (a talker and its UI under `emos run`), plus a
UIServer in this process for the token file's life and uploads. The refusals are checked as an
attacker would try them: no token, a wrong one, ``Origin: null`` (sandboxed frames, local files),
a foreign origin, ``text/plain`` bodies (no CORS preflight), missing or wrong CSRF tokens.
"""
from __future__ import annotations

import asyncio
import io
import json
import os
import stat
import wave
from pathlib import Path
from typing import Any

import aiohttp
import pytest

from emos.core.rpc import RpcClient
from tests.ui.conftest import free_port, run_system

pytestmark = [pytest.mark.process, pytest.mark.timeout(120)]

JSON = {"Content-Type": "application/json"}
# The wire protocol, spelled out here rather than imported: the page and scripts depend on it.
CSRF_HEADER = "X-EMOS-CSRF"


def session_cookie(port: int) -> str:
    return f"emos_ui_session_{port}"


@pytest.fixture(scope="module")
def talker(tmp_path_factory):
    yield from run_system(tmp_path_factory.mktemp("ui-security"), "port_recipe.py")


def call(port: int, method: str, path: str, headers: dict[str, str] | None = None, data: Any = None,
         no_content_type: bool = False) -> tuple[int, str]:
    """One request, no cookies but those in ``headers``; (status, body)."""
    async def go() -> tuple[int, str]:
        async with aiohttp.ClientSession(cookie_jar=aiohttp.DummyCookieJar()) as s:
            skip = ["Content-Type"] if no_content_type else []
            async with s.request(method, f"http://127.0.0.1:{port}{path}", headers=headers or {}, data=data,
                                 allow_redirects=False, skip_auto_headers=skip) as r:
                return r.status, await r.text()
    return asyncio.run(go())


def ws_try(port: int, headers: dict[str, str], params: dict[str, str] | None = None) -> str | int:
    """The websocket handshake's refusal status, or the first text message the server sends."""
    async def go() -> str | int:
        async with aiohttp.ClientSession(cookie_jar=aiohttp.DummyCookieJar()) as s:
            try:
                async with s.ws_connect(f"http://127.0.0.1:{port}/ws", headers=headers, params=params or {}) as ws:
                    msg = await ws.receive(timeout=30)
                    return str(msg.data)
            except aiohttp.WSServerHandshakeError as exc:
                return exc.status
    return asyncio.run(go())


def signed_in(system) -> tuple[dict[str, str], str]:
    """What a script needs: the token and a session cookie (headers), and the session's CSRF token."""
    auth = {"Authorization": f"Bearer {system.token}"}

    async def go() -> tuple[str, str]:
        async with aiohttp.ClientSession(cookie_jar=aiohttp.DummyCookieJar()) as s, \
                s.get(f"http://127.0.0.1:{system.port}/api/session", headers=auth) as r:
            assert r.status == 200, await r.text()
            return r.cookies[session_cookie(system.port)].value, (await r.json())["csrf"]
    session, csrf = asyncio.run(go())
    return {**auth, "Cookie": f"{session_cookie(system.port)}={session}"}, csrf


def talker_state(system) -> str:
    status, body = call(system.port, "GET", "/api/system", {"Authorization": f"Bearer {system.token}"})
    assert status == 200, body
    sock = Path(_runtime_root()) / json.loads(body)["run_id"] / "ctl" / "talker.sock"
    with RpcClient(sock, timeout=5.0) as rpc:
        return rpc.call("get_state")["state"]


def _runtime_root() -> Path:
    from emos.transport.context import runtime_root

    return runtime_root()


def test_loopback_requires_the_access_token(talker):
    port = talker.port
    # The study's one-liner, from any local user or page: it stopped a component.
    status, body = call(port, "POST", "/api/system/talker/stop", {"Origin": "null", "Content-Type": "text/plain"}, data="x")
    assert status in (401, 403), (status, body)
    for path in ("/", "/api/layout", "/api/system", "/api/settings", "/api/stats", "/api/session"):
        status, body = call(port, "GET", path)
        assert status == 401 and "access token required" in body and "ui.token" in body, (path, status, body)
        assert call(port, "GET", path, {"Authorization": "Bearer wrong"})[0] == 401
        assert call(port, "GET", path + "?token=wrong")[0] == 401
    assert ws_try(port, {}) == 401
    status, body = call(port, "POST", "/api/system/talker/stop", JSON, data="{}")
    assert status == 401, (status, body)
    assert talker_state(talker) == "active"
    # With the token: the page, and the printed link signs the browser in (cookie, 303 to /).
    assert call(port, "GET", "/api/layout", {"Authorization": f"Bearer {talker.token}"})[0] == 200
    assert call(port, "GET", "/?token=" + talker.token)[0] == 303


def test_origin_null_and_foreign_origins_are_refused(talker):
    origins = ("null", "http://attacker.example", "http://127.0.0.1:1", "file://", "https://127.0.0.1.attacker.example")
    auth = {"Authorization": f"Bearer {talker.token}"}
    for origin in origins:  # even with the token: the data routes, and the frames' websocket
        for path in ("/api/layout", "/api/system", "/api/settings", "/api/stats", "/"):
            status, body = call(talker.port, "GET", path, {**auth, "Origin": origin})
            assert status == 403 and "cross-origin request refused" in body, (origin, path, status, body)
        assert ws_try(talker.port, {**auth, "Origin": origin}) == 403
    headers, csrf = signed_in(talker)
    own = f"http://127.0.0.1:{talker.port}"
    for origin in origins:
        assert call(talker.port, "GET", "/api/session", {**headers, "Origin": origin})[0] == 403
        status, body = call(talker.port, "POST", "/api/system/talker/stop", {**headers, **JSON, CSRF_HEADER: csrf, "Origin": origin}, data="{}")
        assert status == 403 and "cross-origin" in body, (origin, status, body)
        assert ws_try(talker.port, {**headers, "Origin": origin}, {"csrf": csrf}) == 403
    assert talker_state(talker) == "active"
    assert call(talker.port, "GET", "/api/layout", {**headers, "Origin": own})[0] == 200


def test_posts_need_json_and_the_session_csrf_token(talker):
    headers, csrf = signed_in(talker)
    stop = "/api/system/talker/stop"
    cases = [
        ({**headers, "Content-Type": "text/plain", CSRF_HEADER: csrf}, False, 415, "needs 'Content-Type: application/json' (got text/plain)"),
        ({**headers, CSRF_HEADER: csrf}, True, 415, "no Content-Type"),
        ({**headers, **JSON}, False, 403, f"CSRF token missing: send the page's CSRF token in the {CSRF_HEADER} header"),
        ({**headers, **JSON, CSRF_HEADER: "0" * 64}, False, 403, "wrong CSRF token"),
        ({"Authorization": headers["Authorization"], **JSON, CSRF_HEADER: csrf}, False, 403, "no session cookie"),
    ]
    for h, bare, want, words in cases:
        status, body = call(talker.port, "POST", stop, h, data="{}", no_content_type=bare)
        assert status == want and words in body, (h, status, body)
        assert talker_state(talker) == "active"
    # Uploads keep their own content types, but need the CSRF token too (then: not an input here).
    status, body = call(talker.port, "POST", "/api/upload/words", {**headers, "Content-Type": "audio/wav"}, data=b"RIFF")
    assert status == 403 and "CSRF token missing" in body, (status, body)
    assert call(talker.port, "POST", "/api/upload/words", {**headers, "Content-Type": "audio/wav", CSRF_HEADER: csrf}, data=b"RIFF")[0] == 404
    # Another session's token is not this one's.
    other_headers, other_csrf = signed_in(talker)
    assert other_csrf != csrf
    status, body = call(talker.port, "POST", stop, {**headers, **JSON, CSRF_HEADER: other_csrf}, data="{}")
    assert status == 403 and "wrong CSRF token" in body
    # Everything right: accepted, and it does what it says.
    status, body = call(talker.port, "POST", stop, {**headers, **JSON, CSRF_HEADER: csrf}, data="{}")
    assert status == 200 and json.loads(body)["ok"], body
    assert talker_state(talker) == "inactive"
    status, body = call(talker.port, "POST", "/api/system/talker/start", {**other_headers, "Content-Type": "application/json; charset=utf-8",
                                                                          CSRF_HEADER: other_csrf}, data="{}")
    assert status == 200, body
    assert talker_state(talker) == "active"


def test_the_websocket_needs_the_csrf_token(talker):
    headers, csrf = signed_in(talker)
    assert ws_try(talker.port, headers) == 403
    assert ws_try(talker.port, headers, {"csrf": "nope"}) == 403
    assert ws_try(talker.port, {"Authorization": headers["Authorization"]}, {"csrf": csrf}) == 403  # no session
    first = ws_try(talker.port, {**headers, "Origin": f"http://127.0.0.1:{talker.port}"}, {"csrf": csrf})
    assert isinstance(first, str) and "still talking" in first, first


def test_the_token_file_is_private_while_the_ui_runs(talker):
    status, body = call(talker.port, "GET", "/api/system", {"Authorization": f"Bearer {talker.token}"})
    run_dir = _runtime_root() / json.loads(body)["run_id"]
    path = run_dir / "ui.token"
    st, dst = os.lstat(path), os.lstat(run_dir)
    assert stat.S_ISREG(st.st_mode) and stat.S_IMODE(st.st_mode) == 0o600 and st.st_uid == os.geteuid()
    assert stat.S_IMODE(dst.st_mode) == 0o700 and dst.st_uid == os.geteuid()
    assert path.read_text().strip() == talker.token
    log = talker.log.read_text()
    # The link is printed once; the UI's own log line names the file, not the token.
    assert log.count(talker.token) == 1, log
    assert f"page at http://127.0.0.1:{talker.port}/ (access token in {path})" in log


# ---------------------------------------------------------------- a UIServer in this process
def _server(tmp: Path, published: list) -> Any:
    from emos.actors.ui.config import UIConfig
    from emos.actors.ui.server import UIServer

    config = UIConfig(port=free_port(), token="t0ken-for-this-test-only")
    return UIServer(config, [], {"/voice": "Audio"}, {}, publish=lambda topic, msg: published.append((topic, msg)),
                    control_socket=lambda name: tmp / f"{name}.sock", supervisor_socket=None, own_name="ui",
                    token_file=tmp / "ui.token")


def test_the_token_file_lives_as_long_as_the_server_and_uploads_need_csrf(tmp_path):
    run_dir = tmp_path / "run"
    run_dir.mkdir(mode=0o700)
    published: list = []
    server = _server(run_dir, published)
    port, path = server.config.port, run_dir / "ui.token"
    recording = io.BytesIO()
    with wave.open(recording, "wb") as w:
        w.setnchannels(1), w.setsampwidth(2), w.setframerate(16000)
        w.writeframes(b"\x01\x00" * 160)

    async def scenario() -> None:
        assert not path.exists()
        server.bind()
        await server.start()
        try:
            assert stat.S_IMODE(os.lstat(path).st_mode) == 0o600 and path.read_text().strip() == server.config.token
            auth = {"Authorization": f"Bearer {server.config.token}"}
            async with aiohttp.ClientSession(headers=auth, cookie_jar=aiohttp.CookieJar(unsafe=True)) as s:
                async with s.get(f"http://127.0.0.1:{port}/") as r:
                    page = await r.text()
                csrf = page.split('name="emos-csrf" content="', 1)[1].split('"', 1)[0]
                async with s.head(f"http://127.0.0.1:{port}/") as r:
                    assert r.status == 200
                async with s.get(f"http://127.0.0.1:{port}/api/session") as r:
                    assert (await r.json())["csrf"] == csrf  # one session: the page's and the script's token agree
                url = f"http://127.0.0.1:{port}/api/upload/voice"
                async with s.post(url, data=recording.getvalue(), headers={"Content-Type": "audio/wav"}) as r:
                    assert r.status == 403 and "CSRF token missing" in await r.text()
                assert published == []
                async with s.post(url, data=recording.getvalue(), headers={"Content-Type": "audio/wav", CSRF_HEADER: csrf}) as r:
                    assert r.status == 200, await r.text()
                assert [(t, len(m.data)) for t, m in published] == [("/voice", 320)]
        finally:
            await server.stop()
        assert not path.exists()

    import uvloop

    uvloop.run(scenario())  # the UI component's loop


def test_the_token_file_is_not_written_where_others_could_read_it(tmp_path):
    from emos.actors.ui.tokenfile import TokenFileRefused, write_token_file

    shared = tmp_path / "shared"
    shared.mkdir()
    shared.chmod(0o755)
    with pytest.raises(TokenFileRefused, match=r"has mode 0o755, not 0o700"):
        write_token_file(shared / "ui.token", "secret")
    private = tmp_path / "private"
    private.mkdir(mode=0o700)
    link = tmp_path / "link"
    link.symlink_to(private)
    with pytest.raises(TokenFileRefused, match="is a symbolic link"):
        write_token_file(link / "ui.token", "secret")
    assert list(shared.iterdir()) == [] and list(private.iterdir()) == []
    write_token_file(private / "ui.token", "secret")
    write_token_file(private / "ui.token", "secret2")  # replaced, e.g. by a restarted UI
    assert (private / "ui.token").read_text() == "secret2\n" and [p.name for p in private.iterdir()] == ["ui.token"]
