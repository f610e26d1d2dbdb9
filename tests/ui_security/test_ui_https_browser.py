"""Issue 41 item 2 in a real browser: headless Chromium trusts exactly the run's self-signed
certificate (its public key pinned with --ignore-certificate-errors-spki-list, nothing else
ignored), pairs at /pair with the printed code, gets the page over HTTPS and its websocket over
WSS; a viewer gets the page without controls; a page of another origin cannot open the UI's
websockets nor publish through the browser's cookie. The System tab draws the system graph."""
from __future__ import annotations

import base64
import hashlib
import http.server
import threading
import time
from pathlib import Path

import pytest

from tests.ui.conftest import free_port, headless_chromium
from tests.ui_security.conftest import next_code

pytestmark = [pytest.mark.browser, pytest.mark.process, pytest.mark.timeout(240), pytest.mark.xdist_group("browser")]


@pytest.fixture
def secured_page(secured):
    return secured  # the HTTPS system shared by this folder's tests (conftest.py)


def spki_pin(cert: Path) -> str:
    """base64(SHA-256(SubjectPublicKeyInfo)): how Chromium names one certificate's key."""
    from cryptography import x509
    from cryptography.hazmat.primitives import serialization

    key = x509.load_pem_x509_certificate(cert.read_bytes()).public_key()
    der = key.public_bytes(serialization.Encoding.DER, serialization.PublicFormat.SubjectPublicKeyInfo)
    return base64.b64encode(hashlib.sha256(der).digest()).decode()


@pytest.fixture(scope="module")
def tls_browser(secured):
    # The run's self-signed certificate is trusted by its key's pin, as a paired device would.
    yield from headless_chromium(extra_args=(f"--ignore-certificate-errors-spki-list={spki_pin(secured.cert)}",))


def wait_js(driver, script: str, timeout: float = 30.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        value = driver.execute_script(script)
        if value:
            return value
        time.sleep(0.2)
    raise TimeoutError(f"{script!r} stayed falsy for {timeout} s; page: {driver.execute_script('return document.body.innerText')[:800]}")


def pair_in_browser(driver, system, role: str, name: str) -> None:
    from selenium.webdriver.common.by import By

    driver.delete_all_cookies()
    driver.get(f"{system.base}/pair#code={next_code(system)}")
    assert driver.find_element(By.ID, "pair-code").get_attribute("value")  # filled in from the QR code's address
    assert "code=" not in driver.current_url  # and taken out of the address bar
    driver.find_element(By.ID, "pair-name").send_keys(name)
    driver.find_element(By.CSS_SELECTOR, f"#pair-role option[value={role}]").click()
    driver.find_element(By.ID, "pair-send").click()
    wait_js(driver, "return location.pathname === '/' && document.getElementById('conn-text') && document.getElementById('conn-text').textContent === 'live'")


def test_pairing_and_the_page_over_https_and_wss(secured_page, tls_browser):
    driver = tls_browser
    pair_in_browser(driver, secured_page, "operator", "browser tablet")
    assert driver.execute_script("return location.protocol") == "https:"
    assert wait_js(driver, "return document.getElementById('role').textContent") == "operator · browser tablet"
    wait_js(driver, "const l = document.querySelector('[data-topic=\"/words\"]'); return l && l.textContent.includes('still talking')")
    # The operator's controls are there, and they work over WSS.
    driver.execute_script("window.__sent = sendInput('/question', 'typed on the tablet')")
    wait_js(driver, "return window.emosStats.published.some(p => p.topic === '/question' && p.ok)")
    end = time.monotonic() + 30
    while time.monotonic() < end and not any(r["value"] == "typed on the tablet" for r in secured_page.received()):
        time.sleep(0.2)
    assert any(r["value"] == "typed on the tablet" for r in secured_page.received())
    # The System tab draws the graph: components, topics, the event and its action.
    driver.execute_script("document.getElementById('tab-system').click()")
    wait_js(driver, "return document.querySelector('[data-node=\"component:talker\"]')")
    assert driver.execute_script("return !!document.querySelector('[data-edge=\"component:talker->topic:/words\"]')")
    assert driver.execute_script("return !!document.querySelector('[data-edge=\"topic:/estop->event:estop pressed\"]')")
    assert driver.execute_script("return !!document.querySelector('[data-edge=\"topic:/question->component:recorder\"]')")


def test_a_viewer_gets_the_page_without_controls(secured_page, tls_browser):
    driver = tls_browser
    pair_in_browser(driver, secured_page, "viewer", "wall screen")
    assert wait_js(driver, "return document.getElementById('role').textContent") == "viewer · wall screen"
    wait_js(driver, "const l = document.querySelector('[data-topic=\"/words\"]'); return l && l.textContent.includes('still talking')")
    assert driver.execute_script("return document.querySelectorAll('#inputs [data-input]').length") == 0
    # Even a hand-made websocket message is refused by the server.
    driver.execute_script("window.__r = null; state.requests.set(99, r => window.__r = r); "
                          "state.ws.send(JSON.stringify({op: 'publish', id: 99, topic: '/question', value: 'viewer sneaks'}))")
    answer = wait_js(driver, "return window.__r")
    assert answer["ok"] is False and "may only watch" in answer["error"]
    time.sleep(0.5)
    assert not any(r["value"] == "viewer sneaks" for r in secured_page.received())


class _Attacker(http.server.BaseHTTPRequestHandler):
    page = b""

    def do_GET(self) -> None:  # noqa: N802 (http.server's name)
        self.send_response(200)
        self.send_header("Content-Type", "text/html")
        self.end_headers()
        self.wfile.write(self.page)

    def log_message(self, *args: object) -> None:
        pass


def test_a_page_of_another_origin_cannot_use_the_ui(secured_page, tls_browser):
    driver = tls_browser
    pair_in_browser(driver, secured_page, "operator", "victim browser")  # the browser holds an operator cookie
    wss = secured_page.base.replace("https", "wss")
    _Attacker.page = f"""<!doctype html><script>
      window.results = {{}};
      for (const path of ["/ws", "/api/v1/ws"]) {{
        const ws = new WebSocket("{wss}" + path);
        ws.onopen = () => window.results[path] = "open";
        ws.onclose = e => window.results[path] = window.results[path] || "refused " + e.code;
      }}
      fetch("{secured_page.base}/api/v1/inputs/question", {{method: "POST", credentials: "include", mode: "no-cors",
            headers: {{"Content-Type": "text/plain"}}, body: JSON.stringify({{value: "cross-site"}})}})
        .then(() => window.results.fetch = "sent", e => window.results.fetch = "failed " + e);
    </script>""".encode()
    port = free_port()
    server = http.server.ThreadingHTTPServer(("127.0.0.1", port), _Attacker)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        driver.get(f"http://127.0.0.1:{port}/attack.html")
        results = wait_js(driver, "const r = window.results; return r && r['/ws'] && r['/api/v1/ws'] && r.fetch ? r : null")
    finally:
        server.shutdown()
        server.server_close()
    assert results["/ws"].startswith("refused") and results["/api/v1/ws"].startswith("refused"), results
    time.sleep(0.5)
    assert not any(r["value"] == "cross-site" for r in secured_page.received())
    assert "refused a cross-origin request from 127.0.0.1" in secured_page.log_text()
