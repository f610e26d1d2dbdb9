"""Issue 41 item 2, guessing: 1,000 wrong pairing codes and wrong tokens are all refused, the
client is then refused even the right code until its window passes, and the refusals make a
few log lines, not a thousand. Headless mode (enable_ui(serve_browser=False)) in the same run:
the API, no page."""
from __future__ import annotations

import asyncio
import re

import aiohttp
import pytest

from tests.ui_security.conftest import bearer, client_ssl, request, run_secured

pytestmark = [pytest.mark.process, pytest.mark.timeout(240)]


@pytest.fixture(scope="module")
def headless(tmp_path_factory):
    yield from run_secured(tmp_path_factory.mktemp("ui-headless"), headless=True)


def _guess_many(system, n: int, local_addr: str) -> dict[int, int]:
    """``n`` wrong pairing codes from ``local_addr``, 20 at a time: {status: count}."""
    async def go() -> dict[int, int]:
        counts: dict[int, int] = {}
        conn = aiohttp.TCPConnector(ssl=client_ssl(system.cert), local_addr=(local_addr, 0), limit=20)
        async with aiohttp.ClientSession(connector=conn, cookie_jar=aiohttp.DummyCookieJar()) as s:
            async def one(i: int) -> None:
                guess = f"{i:04d}-AAAA".replace("0", "2").replace("1", "3")
                async with s.post(system.base + "/api/pair", json={"code": guess, "name": "guesser"}) as r:
                    counts[r.status] = counts.get(r.status, 0) + 1
            for start in range(0, n, 20):
                await asyncio.gather(*(one(i) for i in range(start, min(n, start + 20))))
        return counts
    return asyncio.run(go())


def test_a_thousand_wrong_codes_are_refused_and_logged_without_flooding(headless):
    counts = _guess_many(headless, 1000, "127.0.0.7")
    assert sum(counts.values()) == 1000 and set(counts) <= {401, 429}, counts
    assert counts.get(401, 0) <= 30 and counts[429] >= 970, counts  # 30 failures a minute per client, then 429
    # Blocked means blocked: the right code from that client is refused too, and so are tokens.
    status, body, headers = request(headless, "POST", "/api/pair", json_body={"code": headless.code, "name": "guesser"}, local_addr="127.0.0.7")
    assert status == 429 and "too many failed attempts" in body["error"] and int(headers["Retry-After"]) >= 1, body
    status, body, _ = request(headless, "GET", "/api/v1/session", bearer(headless.token), local_addr="127.0.0.7")
    assert status == 429, body
    # Another client is not locked out by this one's guesses (the overall limit is 10x).
    status, body, _ = request(headless, "GET", "/api/v1/session", bearer(headless.token), local_addr="127.0.0.8")
    assert status == 200, body
    # Wrong tokens count the same way.
    statuses = [request(headless, "GET", "/api/v1/session", bearer(f"wrong-{i}"), local_addr="127.0.0.9")[0] for i in range(40)]
    assert statuses.count(401) == 30 and statuses.count(429) == 10, statuses
    log = headless.log_text()
    lines = [line for line in log.splitlines() if "[ui] refused" in line and ("127.0.0.7" in line or "127.0.0.9" in line)]
    # One line per reason and client per 10 s (then with counts): a handful, not 1,040.
    assert 2 <= len(lines) <= 10, lines
    reasons = [re.sub(r"^.*\[ui\] refused (.*?) from (\S+):.*$", r"\1 \2", line) for line in lines]
    assert len(set(reasons)) == len(reasons), lines  # each once (the test takes far less than 10 s)
    # The right code from a client that did not guess still pairs.
    status, body, _ = request(headless, "POST", "/api/pair", json_body={"code": headless.code, "name": "fleet manager"}, local_addr="127.0.0.10")
    assert status == 200 and body["ok"], body


def test_headless_serves_the_api_and_no_page(headless):
    h = bearer(headless.token)
    for path in ("/", "/?token=" + headless.token, "/pair", "/static/app.js"):
        assert request(headless, "GET", path, h, local_addr="127.0.0.11")[0] == 404, path
    assert request(headless, "GET", "/ws", h, local_addr="127.0.0.11")[0] in (403, 404)  # the page's websocket: not there
    for path in ("/api/v1/openapi.json", "/api/v1/session", "/api/v1/graph", "/api/v1/inputs"):
        assert request(headless, "GET", path, h, local_addr="127.0.0.11")[0] == 200, path
    status, body, _ = request(headless, "POST", "/api/v1/inputs/question", h, json_body={"value": "from a fleet manager"}, local_addr="127.0.0.11")
    assert status == 200, body
