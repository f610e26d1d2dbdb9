"""The recipe page in headless Chromium, against a real supervised system.

One recipe and one browser for the whole module; the tests run in file order (the page loaded
by the first is the page the others use).
"""
from __future__ import annotations

import json
import os
import signal
import time
from pathlib import Path

import pytest

from emos.core.rpc import RpcClient
from tests.ui.conftest import ARTIFACTS

# One pytest-xdist worker runs them all, in order (--dist loadgroup): they share one Chromium and
# one UI system per module, and split across two workers they failed to find the page's tabs.
pytestmark = [pytest.mark.browser, pytest.mark.process, pytest.mark.timeout(120), pytest.mark.xdist_group("browser")]


def wait_for(predicate, timeout: float = 15.0, what: str = "condition"):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(0.1)
    raise AssertionError(f"timed out after {timeout} s waiting for {what}")


def received(out: Path, topic: str) -> list:
    if not out.exists():
        return []
    return [json.loads(line)["value"] for line in out.read_text().splitlines() if json.loads(line)["topic"] == topic]


def stats(driver) -> dict:
    return driver.execute_script("return window.emosStats")


def run_dir_of(driver) -> Path:
    from emos.transport.context import runtime_root

    run_id = driver.execute_async_script("fetch('/api/system').then(r => r.json()).then(d => arguments[0](d.run_id))")
    return runtime_root() / run_id


def test_page_loads_offline_and_shows_the_camera(ui_system, browser):
    port = ui_system.port
    browser.get_log("performance")  # drop what the browser did before our page
    # The link printed at start-up, as a user opens it: the token moves into a cookie and out
    # of the address bar; without it (a fresh browser) the page is refused.
    browser.get(f"http://127.0.0.1:{port}/")
    assert "access token required" in browser.page_source
    browser.get_log("browser")  # the refusal's console errors are not the page's
    browser.get(ui_system.link)
    assert browser.current_url == f"http://127.0.0.1:{port}/"
    wait_for(lambda: stats(browser)["frames"].get("/camera", 0) >= 5, what="camera frames on the page")
    # The picture on the canvas is the published one (red), not an empty canvas.
    pixel = browser.execute_script("""
        const c = document.querySelector('canvas.image');
        return Array.from(c.getContext('2d').getImageData(c.width / 2, c.height / 2, 1, 1).data);""")
    assert pixel[0] > 150 and pixel[1] < 100 and pixel[2] < 60, pixel
    # Published -> displayed: the median frame is shown well within a second.
    latencies = sorted(stats(browser)["latencies"])
    assert latencies[len(latencies) // 2] < 1000, latencies
    # Every request the page made went to this server (no CDN, no fonts, nothing external).
    urls = []
    for entry in browser.get_log("performance"):
        message = json.loads(entry["message"])["message"]
        if message["method"] == "Network.requestWillBeSent":
            urls.append(message["params"]["request"]["url"])
    assert urls, "no requests recorded"
    networked = [u for u in urls if u.split(":", 1)[0] in ("http", "https", "ws", "wss", "ftp")]
    outside = [u for u in networked if not u.startswith((f"http://127.0.0.1:{port}/", f"ws://127.0.0.1:{port}/"))]
    assert not outside, outside
    # (Chrome asks for /favicon.ico on the refusal page above, maybe after the drain: our page
    # links /static/favicon.svg, so that 401 is the refusal's, not the page's.)
    severe = [e for e in browser.get_log("browser") if e["level"] == "SEVERE" and "/favicon.ico" not in e["message"]]
    assert not severe, severe
    wait_for(lambda: browser.execute_script("return document.querySelector('#map-canvas') !== null"), what="map view")
    time.sleep(1.0)  # let the map and odometry draw before the picture
    browser.save_screenshot(str(ARTIFACTS / "dashboard.png"))


def test_text_typed_reaches_its_topic_and_the_answer_is_shown(ui_system, browser):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys

    out = ui_system.out
    box = browser.find_element(By.CSS_SELECTOR, "textarea[data-topic='/question']")
    box.send_keys("where is the kitchen?")
    box.send_keys(Keys.ENTER)
    assert wait_for(lambda: "where is the kitchen?" in received(out, "/question"), what="the question on /question")
    log = browser.find_element(By.CSS_SELECTOR, ".log[data-topic='/answer']")
    wait_for(lambda: "echo: where is the kitchen?" in log.text, what="the answer on the page")
    # A streamed reply (StreamingString chunks) is one growing bubble, not one bubble per chunk.
    streamed = browser.find_element(By.CSS_SELECTOR, ".log[data-topic='/reply']")
    wait_for(lambda: "streamed reply to where is the kitchen?" in streamed.text, what="the streamed reply")
    assert len(streamed.find_elements(By.CSS_SELECTOR, ".bubble")) == 1


def test_bool_buttons_publish(ui_system, browser):
    from selenium.webdriver.common.by import By

    out = ui_system.out
    browser.find_element(By.CSS_SELECTOR, "[data-input='/estop'] button[data-value='true']").click()
    assert wait_for(lambda: received(out, "/estop") == [True], what="True on /estop")


def test_microphone_recording_reaches_the_audio_topic(ui_system, browser):
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By

    out = ui_system.out
    button = browser.find_element(By.CSS_SELECTOR, "button[data-record='/voice']")
    ActionChains(browser).click_and_hold(button).perform()
    # Hold for a second of recording, counted from when the page says the microphone is open:
    # opening it takes a while on a loaded machine.
    wait_for(lambda: "Recording" in button.text, what="the microphone open")
    ActionChains(browser).pause(1.0).release().perform()
    sizes = wait_for(lambda: received(out, "/voice"), what="a recording on /voice")
    assert sizes[-1] >= 8000 and sizes[-1] % 2 == 0, sizes  # about a second of 16 kHz 16-bit PCM


def test_click_on_the_map_publishes_a_goal_at_that_point(ui_system, browser):
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By

    out = ui_system.out
    canvas = browser.find_element(By.ID, "map-canvas")
    wait_for(lambda: stats(browser)["frames"].get("/map", 0) >= 1, what="the map on the page")
    # Where world point (3.0, 5.0) is on screen, computed here from the map's geometry (the
    # test recipe's 200x160 cells of 5 cm, origin (-2, -1)) and the canvas' size, not by the page.
    res, w, h, ox, oy = 0.05, 200, 160, -2.0, -1.0
    target = (3.0, 5.0)
    cw, ch = browser.execute_script("return [arguments[0].width, arguments[0].height]", canvas)
    rect = browser.execute_script("const r = arguments[0].getBoundingClientRect(); return [r.width, r.height]", canvas)
    s = min(cw / w, ch / h)
    off_x, off_y = (cw - w * s) / 2, (ch - h * s) / 2
    px = off_x + (target[0] - ox) / res * s
    py = off_y + (h - (target[1] - oy) / res) * s
    css_x, css_y = px * rect[0] / cw, py * rect[1] / ch
    ActionChains(browser).move_to_element_with_offset(canvas, css_x - rect[0] / 2, css_y - rect[1] / 2).click().perform()
    goals = wait_for(lambda: received(out, "/goal"), what="a goal on /goal")
    x, y, frame = goals[-1]
    assert abs(x - target[0]) <= res and abs(y - target[1]) <= res, (x, y)
    assert frame == "map"
    time.sleep(0.3)
    browser.save_screenshot(str(ARTIFACTS / "map_goal.png"))


def test_action_goal_from_the_page_shows_feedback_and_result(ui_system, browser):
    from selenium.webdriver.common.by import By

    out = ui_system.out
    card = browser.find_element(By.CSS_SELECTOR, "[data-input='navigator/action']")
    x, y = card.find_elements(By.CSS_SELECTOR, "input[type=number]")
    x.send_keys("1.25")
    y.send_keys("-0.5")
    card.find_element(By.CSS_SELECTOR, "button[data-send='navigator/action']").click()
    status = card.find_element(By.CSS_SELECTOR, "[data-action-status]")
    wait_for(lambda: status.get_attribute("data-state") == "succeeded", what="the action's result")
    assert "reached 1.25 -0.50" in status.text
    assert received(out, "navigate") == [[1.25, -0.5]]


def test_wrong_input_type_is_refused_with_a_message(ui_system, browser):
    out = ui_system.out
    result = browser.execute_async_script("""
        const done = arguments[0];
        const csrf = document.querySelector('meta[name="emos-csrf"]').content;
        const ws = new WebSocket('ws://' + location.host + '/ws?csrf=' + encodeURIComponent(csrf));
        ws.onopen = () => ws.send(JSON.stringify({op: 'publish', id: 7, topic: '/estop', value: 'yes'}));
        ws.onmessage = ev => { if (typeof ev.data === 'string') { const m = JSON.parse(ev.data); if (m.op === 'result') { ws.close(); done(m); } } };""")
    assert result["ok"] is False and "/estop" in result["error"] and "true or false" in result["error"]
    assert received(out, "/estop") == [True]  # nothing more was published


def test_settings_change_reaches_the_component_and_bad_values_are_refused(ui_system, browser):
    from selenium.webdriver.common.by import By

    browser.find_element(By.ID, "tab-settings").click()
    card = wait_for(lambda: browser.find_elements(By.CSS_SELECTOR, "[data-component='recorder']"), what="the recorder's settings")[0]
    field = card.find_element(By.CSS_SELECTOR, "input[name='heartbeat_rate']")
    sock = run_dir_of(browser) / "ctl" / "recorder.sock"

    def config() -> dict:
        with RpcClient(sock, timeout=5.0) as rpc:
            return rpc.call("info")["config"]

    assert config()["heartbeat_rate"] == 10.0
    field.clear()
    field.send_keys("4")
    card.find_element(By.CSS_SELECTOR, "button[data-apply='recorder']").click()
    wait_for(lambda: card.find_elements(By.CSS_SELECTOR, ".okmsg"), what="the applied message")
    assert config()["heartbeat_rate"] == 4.0
    # Out of range: refused with the validator's words, the old value kept on both sides.
    field.clear()
    field.send_keys("0")
    card.find_element(By.CSS_SELECTOR, "button[data-apply='recorder']").click()
    error = wait_for(lambda: card.find_elements(By.CSS_SELECTOR, ".error"), what="the refusal")[0]
    assert "heartbeat_rate" in error.text and "[0.1, 10000.0]" in error.text, error.text
    assert config()["heartbeat_rate"] == 4.0
    assert field.get_attribute("value") == "4"
    browser.save_screenshot(str(ARTIFACTS / "settings.png"))


def test_system_view_and_the_ui_coming_back_after_a_kill(ui_system, browser):
    from selenium.webdriver.common.by import By

    browser.find_element(By.ID, "tab-system").click()

    # The table is redrawn every second: read and click through fresh look-ups each time.
    def row_text(name: str) -> str:
        return browser.execute_script(f"const r = document.querySelector(\"tr[data-component='{name}']\"); return r ? r.innerText : ''")

    def cells(name: str) -> list:
        return browser.execute_script(f"return Array.from(document.querySelectorAll(\"tr[data-component='{name}'] td\")).map(td => td.innerText)")

    def press(name: str, action: str) -> None:
        browser.execute_script(f"document.querySelector(\"tr[data-component='{name}'] button[data-action='{action}']\").click()")

    wait_for(lambda: "HEALTHY" in row_text("camera"), what="camera healthy")
    browser.save_screenshot(str(ARTIFACTS / "system.png"))
    # Stop and start are the lifecycle's deactivate and activate; restart is a fresh process.
    press("camera", "stop")
    wait_for(lambda: (cells("camera") or [None] * 3)[2] == "inactive", what="camera inactive")
    press("camera", "start")
    wait_for(lambda: (cells("camera") or [None] * 3)[2] == "active", what="camera active again")
    world_pid = cells("world")[1]
    press("world", "restart")
    wait_for(lambda: (c := cells("world")) and c[1] not in (world_pid, "-") and c[2] == "active", timeout=30,
             what="world restarted with a new pid")
    # Counted as asked for from the page, not as a crash.
    world = browser.execute_async_script("""
        const done = arguments[arguments.length - 1];
        const find = n => n.name === "world" ? n : (n.children || []).map(find).find(x => x);
        fetch("/api/system").then(r => r.json()).then(d => done(find(d.tree)));""")
    assert world["restart_reasons"] == {"requested": 1} and "requested by ui" in world["last_restart_detail"], world
    # A second tab gets its own stream.
    first = browser.current_window_handle
    browser.switch_to.new_window("tab")
    browser.get(f"http://127.0.0.1:{ui_system.port}/")  # signed in by the cookie, no token in the address
    wait_for(lambda: stats(browser)["frames"].get("/camera", 0) >= 3, what="frames in the second tab")
    browser.close()
    browser.switch_to.window(first)
    # Kill the UI's process: its supervisor starts a new one and the page reconnects by itself.
    ui_pid = browser.execute_async_script(
        "fetch('/api/system').then(r => r.json()).then(d => arguments[0](d.tree.children.find(g => g.name === 'ui').children[0].pid))")
    connects = stats(browser)["connects"]
    os.kill(ui_pid, signal.SIGKILL)
    wait_for(lambda: stats(browser)["connects"] > connects, timeout=30, what="the page reconnecting")
    before = stats(browser)["frames"]["/camera"]
    wait_for(lambda: stats(browser)["frames"]["/camera"] > before + 3, what="frames after the reconnect")


ELSEWHERE = """<!doctype html><title>another page on this machine</title>
<iframe sandbox="allow-scripts" src="/frame"></iframe>"""
# Sandboxed (no allow-same-origin): its requests say "Origin: null", as a local HTML file's do.
FRAME = """<!doctype html><script>
addEventListener("message", async ev => {
  const port = ev.data, out = { origin: self.origin };
  try {
    await fetch(`http://127.0.0.1:${port}/api/system/camera/stop`, { method: "POST", mode: "no-cors", credentials: "include",
      headers: { "Content-Type": "text/plain" }, body: "{}" });
    out.post = "sent";
  } catch (e) { out.post = String(e); }
  out.ws = await new Promise(resolve => {
    const ws = new WebSocket(`ws://127.0.0.1:${port}/ws`);
    ws.onmessage = () => { resolve("data"); ws.close(); };
    ws.onclose = () => resolve("refused");
  });
  parent.postMessage(out, "*");
});
</script>"""


def test_pages_of_other_origins_cannot_drive_the_robot_or_watch_it(ui_system, browser):
    """Issue 31: a page of another origin in the user's browser (here on another port of this
    machine, so the browser even sends it the UI's SameSite cookie) and a sandboxed frame in it
    (``Origin: null``) try the study's attack: stop the camera with a text/plain POST (no CORS
    preflight), and read the robot's streams over the websocket."""
    import http.server
    import threading

    class Elsewhere(http.server.BaseHTTPRequestHandler):
        def do_GET(self):
            body = (FRAME if self.path == "/frame" else ELSEWHERE).encode()
            self.send_response(200)
            self.send_header("Content-Type", "text/html")
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, *args):
            pass

    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Elsewhere)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    first = browser.current_window_handle
    browser.switch_to.new_window("tab")
    try:
        browser.get(f"http://127.0.0.1:{server.server_address[1]}/")
        result = browser.execute_async_script("""
            const [port, done] = arguments, ui = `http://127.0.0.1:${port}`, top = {};
            fetch(ui + "/api/system/camera/stop", { method: "POST", mode: "no-cors", credentials: "include",
                  headers: { "Content-Type": "text/plain" }, body: "{}" })
              .then(() => { top.post = "sent"; }, e => { top.post = String(e); })
              .then(() => new Promise(resolve => {
                const ws = new WebSocket(`ws://127.0.0.1:${port}/ws`);
                ws.onmessage = () => { resolve("data"); ws.close(); };
                ws.onclose = () => resolve("refused");
              }))
              .then(ws => {
                top.ws = ws;
                addEventListener("message", ev => done({ top, frame: ev.data }));
                document.querySelector("iframe").contentWindow.postMessage(port, "*");
              });""", ui_system.port)
    finally:
        browser.close()
        browser.switch_to.window(first)
        server.shutdown()
        server.server_close()
        thread.join(10)
    assert result["frame"]["origin"] == "null", result  # the frame really was an opaque origin
    assert result["top"]["ws"] == "refused" and result["frame"]["ws"] == "refused", result
    with RpcClient(run_dir_of(browser) / "ctl" / "camera.sock", timeout=5.0) as rpc:
        assert rpc.call("get_state")["state"] == "active"  # the POSTs (sent, the answers opaque) changed nothing
    # The UI's own page, meanwhile, still streams.
    before = stats(browser)["frames"]["/camera"]
    wait_for(lambda: stats(browser)["frames"]["/camera"] > before + 3, what="frames on the UI's own page")


def test_a_page_that_never_confirms_gets_no_backlog(ui_system):
    """A stalled page is sent at most ``frames_in_flight`` frames while the camera goes on."""
    import asyncio

    import aiohttp

    port = ui_system.port

    async def scenario() -> tuple[int, int, int]:
        # A script signs in with the token and the session's CSRF token, as the page does.
        headers = {"Authorization": f"Bearer {ui_system.token}"}
        async with aiohttp.ClientSession(headers=headers, cookie_jar=aiohttp.CookieJar(unsafe=True)) as session:
            async with session.get(f"http://127.0.0.1:{port}/api/session") as r:
                csrf = (await r.json())["csrf"]
            async def camera_received() -> int:
                async with session.get(f"http://127.0.0.1:{port}/api/stats") as r:
                    return next(h["received"] for h in (await r.json())["hubs"] if h["topic"] == "/camera")

            async with session.ws_connect(f"http://127.0.0.1:{port}/ws", params={"csrf": csrf}) as ws:
                before = await camera_received()
                frames = 0
                deadline = asyncio.get_running_loop().time() + 2.0
                while (left := deadline - asyncio.get_running_loop().time()) > 0:
                    try:
                        msg = await ws.receive(timeout=left)
                    except TimeoutError:
                        break
                    if msg.type == aiohttp.WSMsgType.BINARY and b'"/camera"' in msg.data[:200]:
                        frames += 1  # never acknowledged
                return frames, before, await camera_received()

    frames, before, after = asyncio.run(scenario())
    assert 1 <= frames <= 2, frames  # UIConfig.frames_in_flight defaults to 2
    assert after - before >= 10, (before, after)  # the topic kept flowing into the UI meanwhile


def test_topic_plot_records_a_field_of_the_running_system(ui_system, tmp_path):
    """`emos topic plot` (here against the UI test system): a CSV of odometry x, and a clear
    error for a field the message does not have."""
    import subprocess
    import sys
    import urllib.request

    request = urllib.request.Request(f"http://127.0.0.1:{ui_system.port}/api/system", headers={"Authorization": f"Bearer {ui_system.token}"})
    with urllib.request.urlopen(request, timeout=10) as r:
        run_id = json.loads(r.read())["run_id"]
    out = tmp_path / "odom.csv"
    cmd = [sys.executable, "-m", "emos.tools.cli", "topic", "plot", "--run", run_id, "/odom"]
    done = subprocess.run(cmd + ["pose.pose.position.x", "--duration", "2.5", "--output", str(out)], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    rows = out.read_text().splitlines()
    assert rows[0] == "t_s,pose.pose.position.x" and len(rows) >= 2
    assert float(rows[1].split(",")[1]) == 1.0  # the test recipe's robot stands at x = 1
    bad = subprocess.run(cmd + ["pose.pose.positon.x", "--duration", "2.5", "--output", str(out)], capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "Pose has no field 'positon'" in bad.stderr
