"""
``accelcal serve`` in a real headless Chromium (Debian's chromium + chromium-driver, selenium).

Two tabs are two operators with different images; a drag pans the view; closing a tab
frees its view; the drag-to-new-image latency is measured (printed; no timing asserts).
Skipped, with the reason, where selenium, chromium or chromedriver is missing
(``apt-get install chromium chromium-driver``; selenium is in tools/requirements-ros.txt).
"""
import math
import shutil
import time

from accelcal_ros.camera.rig import ring_rig
from accelcal_ros.panorama import render
from accelcal_ros.panorama.serve import ViewServer
from accelcal_ros.panorama.view_set import ViewSet
import numpy as np
import pytest

webdriver = pytest.importorskip('selenium.webdriver', reason='selenium is not installed')
CHROMIUM = shutil.which('chromium') or shutil.which('chromium-browser')
DRIVER = shutil.which('chromedriver')
pytestmark = pytest.mark.skipif(not (CHROMIUM and DRIVER), reason='no chromium/chromedriver '
                                '(Debian: apt-get install chromium chromium-driver)')


@pytest.fixture(scope='module')
def server():
    """Serve a rendered 3-camera rig (one still frame set) on a free local port."""
    rig = ring_rig(3, 320, 240, 275.0, 45.0)
    scene = render.make_scene(1800, 900, seed=6)
    frames = [(render.render_camera_views(scene, rig, 0.02, 0.08), 0.02, 0.08, 0.0)]
    srv = ViewServer(ViewSet(rig, max_views=4, width=320, height=240), frames, fps=10.0)
    srv.start('127.0.0.1', 0)
    yield srv
    srv.stop()


@pytest.fixture(scope='module')
def browser():
    """Start headless Chromium through chromedriver."""
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for arg in ('--headless=new', '--no-sandbox', '--disable-gpu', '--disable-dev-shm-usage',
                '--window-size=800,600'):
        options.add_argument(arg)
    driver = webdriver.Chrome(service=Service(DRIVER), options=options)
    driver.set_script_timeout(30)
    yield driver
    driver.quit()


def _wait(predicate, timeout=30.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(0.05)
    return predicate()


def _shown(driver):
    """Return the image the tab shows (read off its <canvas>) as a grey array."""
    data = driver.execute_script(
        "const c = document.getElementById('view');"
        "const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;"
        'const g = []; for (let k = 0; k < d.length; k += 4) g.push(d[k] + d[k + 1] + d[k + 2]);'
        'return [c.width, c.height, g];')
    width, height, grey = data
    return np.array(grey, float).reshape(height, width) / 3.0


def _info(driver):
    return driver.execute_script('return window.accelcal && window.accelcal.info();')


def test_tabs_are_operators_drag_pans_and_closing_frees_the_view(server, browser):
    """Two tabs: different images; a drag moves one view only; closing a tab frees it."""
    from selenium.webdriver.common.action_chains import ActionChains

    browser.get(server.url)
    assert _wait(lambda: _info(browser)), browser.page_source[:500]
    first = browser.current_window_handle
    browser.switch_to.new_window('tab')
    browser.get(server.url)
    assert _wait(lambda: _info(browser))
    second = browser.current_window_handle
    assert _wait(lambda: len(server.views.names()) == 2)
    # the second tab turns right with the keyboard: its own view, a different image
    browser.find_element('tag name', 'body').send_keys('\ue014' * 5)  # ArrowRight x 5
    assert _wait(lambda: _info(browser)['az'] > 20.0)
    image_2 = _shown(browser)
    browser.switch_to.window(first)
    info_1 = _info(browser)
    assert abs(info_1['az']) < 1e-9
    image_1 = _shown(browser)
    assert np.abs(image_1 - image_2).mean() > 5.0
    # the HUD draws pose and live fps; the horizon line is on the overlay
    hud = browser.find_element('id', 'hud').text
    assert 'az 0.0' in hud and 'fov 60.0' in hud and 'fps' in hud
    # drag 80 px to the left: the view turns right by about 80 / f rad; measure latency
    stage = browser.find_element('id', 'stage')
    for step in range(4):
        before = browser.execute_script('return window.accelcal.latencies().length;')
        ActionChains(browser).move_to_element(stage).click_and_hold().move_by_offset(
            -20, 0).release().perform()
        assert _wait(lambda: browser.execute_script(
            'return window.accelcal.latencies().length;') > before)
    latencies = browser.execute_script('return window.accelcal.latencies();')
    shown_w = browser.execute_script("return document.getElementById('view').clientWidth;")
    f = (shown_w / 2) / math.tan(math.radians(30))
    expected = math.degrees(80 / f)
    assert _wait(lambda: abs(_info(browser)['az'] - expected) < 0.5), (_info(browser), expected)
    assert np.abs(_shown(browser) - image_1).mean() > 3.0
    print(f'\ndrag to new image on screen: median {np.median(latencies):.1f} ms, max '
          f'{np.max(latencies):.1f} ms ({len(latencies)} drags, measured in the page)')
    # the other tab did not move
    name_1, name_2 = server.views.names()
    assert server.views.views[name_2].pose.degrees()[0] > 20.0
    # closing tab 2 frees its view; tab 1 keeps its own
    browser.switch_to.window(second)
    browser.close()
    browser.switch_to.window(first)
    assert _wait(lambda: server.views.names() == [name_1]), server.views.names()
    browser.find_element('tag name', 'body').send_keys('r')
    assert _wait(lambda: abs(_info(browser)['az']) < 1e-9)
