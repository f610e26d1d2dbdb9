"""A running UI recipe and one headless Chromium shared by a test module."""
from __future__ import annotations

import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import NamedTuple
from urllib.parse import parse_qs, urlsplit

import pytest

HERE = Path(__file__).parent
ROOT = HERE.parent.parent
ARTIFACTS = Path(os.environ.get("EMOS_TEST_ARTIFACTS", ROOT / "test-artifacts")) / "ui"
CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
CHROMEDRIVER = shutil.which("chromedriver") or "/usr/bin/chromedriver"
CHROME_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                "--disable-background-networking", "--disable-component-update", "--disable-sync", "--window-size=1400,1000",
                # A fake microphone (a beep), allowed without a prompt: the page's recorder is tested.
                "--use-fake-device-for-media-stream", "--use-fake-ui-for-media-stream")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_http(port: int, timeout: float = 60.0, proc: subprocess.Popen | None = None) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if proc is not None and proc.poll() is not None:
            raise RuntimeError(f"the recipe exited with code {proc.returncode}: {proc.stdout.read() if proc.stdout else ''}")
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=1.0):
                return
        except OSError:
            time.sleep(0.2)
    raise TimeoutError(f"nothing listens on port {port} after {timeout} s")


LINK_RE = re.compile(r"EMOS UI: (http://\S+)")


def wait_link(log_path: Path, proc: subprocess.Popen, timeout: float = 60.0) -> str:
    """The sign-in link the launcher prints once at bringup (``EMOS UI: http://...?token=...``)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        m = LINK_RE.search(log_path.read_text()) if log_path.exists() else None
        if m:
            return m.group(1)
        if proc.poll() is not None:
            raise RuntimeError(f"the recipe exited with code {proc.returncode}: {log_path.read_text()[-3000:]}")
        time.sleep(0.2)
    raise TimeoutError(f"no 'EMOS UI: <link>' line in {log_path} after {timeout} s")


def token_of(link: str) -> str:
    return parse_qs(urlsplit(link).query).get("token", [""])[0]


class UISystem(NamedTuple):
    port: int
    out: Path
    proc: subprocess.Popen
    link: str  # http://127.0.0.1:<port>/?token=...
    log: Path

    @property
    def token(self) -> str:
        return token_of(self.link)


def start_recipe(recipe: Path, env_extra: dict[str, str], log_path: Path) -> subprocess.Popen:
    env = dict(os.environ, **env_extra)
    with open(log_path, "w") as log:  # the child writes to its own copy of the descriptor
        return subprocess.Popen([sys.executable, "-m", "emos.tools.cli", "run", str(recipe)], env=env, stdout=log,
                                stderr=subprocess.STDOUT, start_new_session=True, cwd=ROOT)


def stop_recipe(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(20)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(5)


def run_system(tmp: Path, recipe: str):
    """Run a test recipe under `emos run` and yield its :class:`UISystem` (stopped afterwards)."""
    port, out = free_port(), tmp / "received.jsonl"
    env = {"EMOS_UI_TEST_PORT": str(port), "EMOS_UI_TEST_OUT": str(out), "EMOS_HOME": str(tmp / "home")}
    proc = start_recipe(HERE / recipe, env, tmp / "recipe.log")
    try:
        link = wait_link(tmp / "recipe.log", proc)
        wait_http(port, proc=proc)
        yield UISystem(port, out, proc, link, tmp / "recipe.log")
    finally:
        stop_recipe(proc)
        print((tmp / "recipe.log").read_text()[-3000:])


@pytest.fixture(scope="module")
def ui_system(tmp_path_factory):
    """The test recipe (camera, map, recorder, navigator) running under `emos run`."""
    yield from run_system(tmp_path_factory.mktemp("ui"), "ui_recipe.py")


def headless_chromium(extra_args=(), capabilities=None):
    """A headless Chromium driven by chromedriver (a generator: yields the driver, quits it and
    removes its profile when closed); skips the test where Chromium is not installed."""
    if not (os.path.exists(CHROMIUM) and os.path.exists(CHROMEDRIVER)):
        pytest.skip("headless Chromium is not installed (scripts/setup.sh --test installs chromium and chromium-driver)")
    webdriver = pytest.importorskip("selenium.webdriver")
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    for flag in (*CHROME_FLAGS, *extra_args):
        options.add_argument(flag)
    profile = tempfile.mkdtemp(prefix="emos-chromium-")
    options.add_argument(f"--user-data-dir={profile}")
    options.binary_location = CHROMIUM
    for name, value in (capabilities or {}).items():
        options.set_capability(name, value)
    driver = webdriver.Chrome(options=options, service=Service(CHROMEDRIVER))
    driver.set_page_load_timeout(30)
    try:
        yield driver
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)


@pytest.fixture(scope="module")
def browser():
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    yield from headless_chromium(capabilities={"goog:loggingPrefs": {"performance": "ALL", "browser": "ALL"}})
