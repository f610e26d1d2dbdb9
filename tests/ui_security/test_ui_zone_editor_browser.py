"""Issue 39's zone editor in the web UI, in real headless Chromium: an operator draws a keepout and
a speed zone as polygons over the map (real clicks on the canvas), saves them, changes the speed
zone's limit and removes the keepout; the masks beside the map are written by the same code as
`emos map zones` (which lists the result), and a viewer sees the zones but can change nothing,
not even with a hand-made request."""
from __future__ import annotations

import subprocess
import sys
import time

import numpy as np
import pytest

from tests.ui.conftest import headless_chromium
from tests.ui_security.conftest import ROOT, run_secured
from tests.ui_security.test_ui_https_browser import pair_in_browser, wait_js

pytestmark = [pytest.mark.browser, pytest.mark.process, pytest.mark.timeout(300), pytest.mark.xdist_group("browser")]


@pytest.fixture(scope="module")
def zone_system(tmp_path_factory):
    from emos.actors.nav.maps import save_map
    from emos.actors.nav.maps.grid import OccupancyGridMap

    tmp = tmp_path_factory.mktemp("ui-zones")
    cells = np.zeros((80, 100), np.int8)  # 5 m x 4 m at 5 cm, origin (-1, -1)
    cells[0, :] = cells[-1, :] = cells[:, 0] = cells[:, -1] = 100
    map_yaml = save_map(OccupancyGridMap(data=cells, resolution=0.05, origin=(-1.0, -1.0, 0.0)), tmp / "office.yaml")
    for system in run_secured(tmp, https=False, extra_env={"EMOS_UI_TEST_ZONES_MAP": str(map_yaml)}):
        yield system, map_yaml


@pytest.fixture(scope="module")
def browser():
    yield from headless_chromium()


def click_world(driver, x: float, y: float) -> None:
    """A real mouse click on the map canvas where world point (x, y) is drawn."""
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By

    canvas = driver.find_element(By.ID, "map-canvas")
    dx, dy = driver.execute_script(
        "const c = document.getElementById('map-canvas'), r = c.getBoundingClientRect(), p = state.map.toCanvas(arguments[0], arguments[1]);"
        "return [p[0] * r.width / c.width - r.width / 2, p[1] * r.height / c.height - r.height / 2];", x, y)
    ActionChains(driver).move_to_element_with_offset(canvas, round(dx), round(dy)).click().perform()


def draw_zone(driver, name: str, kind: str, corners: list[tuple[float, float]], value: float | None = None) -> None:
    from selenium.webdriver.common.by import By

    driver.find_element(By.ID, "zone-name").send_keys(name)
    driver.find_element(By.CSS_SELECTOR, f"#zone-kind option[value={kind}]").click()
    if value is not None:
        driver.find_element(By.ID, "zone-value").send_keys(str(value))
    driver.find_element(By.ID, "zone-draw").click()
    for x, y in corners:
        click_world(driver, x, y)
    assert driver.execute_script("return window.emosZones.draft.length") == len(corners)
    driver.find_element(By.ID, "zone-save").click()
    wait_js(driver, f"return document.querySelector('[data-zone=\"{name}\"]')")


def zones_on_disk(map_yaml) -> dict:
    from emos.actors.nav.costmap.mask_io import load_zones

    zones, _ = load_zones(map_yaml)
    return {z.name: z for z in zones}


def test_an_operator_draws_edits_and_removes_zones_a_viewer_only_watches(zone_system, browser):
    from selenium.webdriver.common.by import By

    from emos.actors.nav.costmap.filters import load_filter_mask
    from emos.actors.nav.costmap.mask_io import zone_mask_paths

    system, map_yaml = zone_system
    driver = browser
    pair_in_browser(driver, system, "operator", "zone tablet")
    wait_js(driver, "return document.getElementById('zones') && state.map && state.map.toCanvas(0, 0)")  # the map arrived
    driver.execute_script("document.getElementById('map-canvas').scrollIntoView({block: 'center'})")

    kitchen = [(0.0, 0.0), (1.5, 0.0), (1.5, 1.0), (0.0, 1.0)]
    draw_zone(driver, "kitchen", "keepout", kitchen)
    hall = [(2.0, 0.0), (3.5, 0.0), (2.75, 2.0)]
    draw_zone(driver, "hall", "speed", hall, value=40)
    saved = zones_on_disk(map_yaml)
    assert set(saved) == {"kitchen", "hall"} and saved["kitchen"].kind == "keepout" and saved["hall"].value == 40.0
    for got, want in ((saved["kitchen"].polygon, kitchen), (saved["hall"].polygon, hall)):
        assert np.allclose(np.asarray(got), np.asarray(want), atol=0.05), (got, want)  # a click is a pixel: ~1 cm here
    keepout = load_filter_mask(zone_mask_paths(map_yaml)["keepout"], "keepout")
    inside, outside = keepout.values_at(np.array([[0.75, 0.5], [3.0, 2.5]]))
    assert inside == 100 and outside == 0 and "kitchen" in keepout.zone_name_at(np.array([0.75, 0.5]))  # rasterized as Nav2 reads it

    # Change the speed limit (same outline), then remove the keepout zone.
    driver.find_element(By.CSS_SELECTOR, '[data-zone-edit="hall"]').click()
    value = driver.find_element(By.ID, "zone-value")
    value.clear()
    value.send_keys("30")
    driver.find_element(By.ID, "zone-save").click()
    wait_js(driver, "const r = document.querySelector('[data-zone=\"hall\"]'); return r && r.textContent.includes('30')")
    assert zones_on_disk(map_yaml)["hall"].value == 30.0
    assert np.allclose(np.asarray(zones_on_disk(map_yaml)["hall"].polygon), np.asarray(hall), atol=0.05)
    driver.find_element(By.CSS_SELECTOR, '[data-zone-remove="kitchen"]').click()
    wait_js(driver, "return !document.querySelector('[data-zone=\"kitchen\"]')")
    assert set(zones_on_disk(map_yaml)) == {"hall"}
    # A bad edit is refused with the reason shown, and nothing is written.
    driver.execute_script("window.__z = null; postJSON('/api/zones', {op: 'set', name: 'hall', value: 250}).then(r => r.json()).then(b => window.__z = b)")
    answer = wait_js(driver, "return window.__z")
    assert answer["ok"] is False and "hall" in answer["error"], answer
    assert zones_on_disk(map_yaml)["hall"].value == 30.0

    # The files are the ones `emos map zones` edits: it lists what the page saved.
    listed = subprocess.run([sys.executable, "-m", "emos.tools.cli", "map", "zones", str(map_yaml), "list"], capture_output=True, text=True,
                            timeout=60, cwd=ROOT)
    assert listed.returncode == 0 and "hall" in listed.stdout and "30%" in listed.stdout and "kitchen" not in listed.stdout, listed

    # A viewer: the zones are drawn and listed, with no controls; a hand-made edit gets 403.
    pair_in_browser(driver, system, "viewer", "zone wall screen")
    wait_js(driver, "return document.querySelector('[data-zone=\"hall\"]')")
    assert driver.execute_script("return document.querySelectorAll('#zone-save, #zone-draw, [data-zone-edit], [data-zone-remove]').length") == 0
    driver.execute_script("window.__v = null; postJSON('/api/zones', {op: 'remove', name: 'hall'}).then(r => window.__v = r.status)")
    assert wait_js(driver, "return window.__v") == 403
    time.sleep(0.5)
    assert set(zones_on_disk(map_yaml)) == {"hall"}
    end = time.monotonic() + 30  # the refusal is logged (bounds a hang only)
    while time.monotonic() < end and "refused a viewer's change" not in system.log_text():
        time.sleep(0.2)
    assert "refused a viewer's change" in system.log_text() and "POST /api/zones" in system.log_text()
