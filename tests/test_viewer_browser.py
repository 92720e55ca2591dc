"""The viewer's page in a real browser: headless Chromium (Debian's `chromium` and
`chromium-driver`, driven by selenium: `pip install -e '.[browser]'`) loads `conag view`,
live and over a recording, and the tests read the canvas's pixels where the world says a
filled site, an empty one, a cue and an agent are, click a disc away, and scrub the timeline.

Skipped, saying why, where Chromium, its driver or selenium is missing (`.ci/run` installs
them). `CONAG_SCREENSHOT=PATH` keeps the screenshot of the recorded Fig. 19 build
(the README's is docs/viewer.png).
"""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
from contextlib import contextmanager

import pytest

from conag.recording.mcap_log import McapRecorder
from conag.viewer.scene import layer_cells
from conag.viewer.server import LiveFeed, ViewerServer
from protocol import encode, keys
from tests.conftest import ROOT, SCENARIOS, RunningWorld, make, wait_until
from tests.test_viewer import LAYOUT, view

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
CHROMEDRIVER = shutil.which("chromedriver") or "/usr/bin/chromedriver"
COLOURS = {"filled": (0xE0, 0xA1, 0x00), "site": (0xF2, 0xD2, 0x7A), "agent": (0x6A, 0x3D, 0x9A),
           "brick": (0xB5, 0x46, 0x2F), "food": (0x3A, 0x9D, 0x23), "blank": (0, 0, 0),  # blank: transparent canvas
           "cue_site": (0x00, 0x83, 0x8F), "cue_supply": (0xEF, 0x6C, 0x00)}


def _missing() -> str | None:
    if not (os.path.exists(CHROMIUM) and os.path.exists(CHROMEDRIVER)):
        return "no Chromium: apt-get install chromium chromium-driver (as .ci/run does)"
    try:
        import selenium  # noqa: F401 -- only whether it is there
    except ImportError:
        return "no selenium: pip install -e '.[browser]'"
    return None


# Each starts or drives a browser: seconds, so the slow tier.
pytestmark = [pytest.mark.skipif(_missing() is not None, reason=_missing() or ""), pytest.mark.slow]


@pytest.fixture(scope="module")
def browser():
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                "--window-size=1240,1000", "--force-device-scale-factor=1"):
        opts.add_argument(arg)
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=opts)
    driver.set_script_timeout(10)
    try:
        yield driver
    finally:
        driver.quit()


def pixel(driver, x: float, y: float) -> tuple[int, int, int]:
    """The canvas's colour at world point (x, y), as the page maps the world to its canvas."""
    return tuple(driver.execute_script("""
        const [px, py] = window.viewer.toCanvas(arguments[0], arguments[1]);
        const ctx = document.getElementById('world').getContext('2d');
        const d = ctx.getImageData(Math.round(px), Math.round(py), 1, 1).data;
        return [d[0], d[1], d[2]];""", x, y))


def near(rgb, name: str, tol: int = 12) -> bool:
    return all(abs(a - b) <= tol for a, b in zip(rgb, COLOURS[name]))


def picture(driver) -> dict:
    return driver.execute_script("return window.viewer.picture")


def click_world(driver, x: float, y: float) -> None:
    """A real mouse click on the canvas at world point (x, y)."""
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By

    canvas = driver.find_element(By.ID, "world")
    px, py = driver.execute_script("return window.viewer.toCanvas(arguments[0], arguments[1])", x, y)
    ActionChains(driver).move_to_element_with_offset(
        canvas, int(px - canvas.size["width"] / 2), int(py - canvas.size["height"] / 2)).click().perform()


def check_drawn_where_the_world_says(driver, v) -> None:
    """Every filled site, empty site and live agent of the WorldView `v` shows on the canvas
    (sites with a body on them aside: the body is drawn on top)."""
    for x, y, filled in zip(v.site_xs, v.site_ys, v.site_filled):
        if any(math.hypot(ax - x, ay - y) < 1.0 for ax, ay in zip(v.agent_x, v.agent_y)):
            continue
        corner = pixel(driver, x + 0.45, y - 0.45)  # inside the cell, outside a disc on it
        assert near(corner, "filled" if filled else "site"), (x, y, filled, corner)
        if filled:
            assert near(pixel(driver, x, y), "brick"), (x, y)  # and the brick on it
    for aid, x, y, h in zip(v.agent_ids, v.agent_x, v.agent_y, v.agent_heading):
        behind = pixel(driver, x - 0.18 * math.cos(h), y - 0.18 * math.sin(h))  # clear of the heading line
        assert near(behind, "agent"), (aid, x, y, behind)


@contextmanager
def live_page(bus, browser, world):
    """`world` served over `bus` to a live viewer, its page open in `browser` with a first
    picture drawn; yields the RunningWorld, and closes the feed and the world after."""
    rw = RunningWorld(world, bus.server_session())
    feed = LiveFeed(bus.client_session(), "w0").start()
    wait_until(lambda: feed.scene.view is not None or feed.refresh(0.5), what="the world's first view")
    try:
        with ViewerServer(feed).serve_in_thread() as server:
            browser.get(server.url)
            wait_until(lambda: browser.execute_script("return window.viewer && window.viewer.frames > 0"),
                       what="the page's first picture")
            yield rw
    finally:
        feed.close()
        rw.close()


def test_the_live_page_draws_the_world_and_a_click_removes_a_disc(bus, browser):
    from selenium.webdriver.common.by import By

    world = make(LAYOUT)
    world.attach("a1")
    with live_page(bus, browser, world) as rw:
        truth = rw.world.view()
        check_drawn_where_the_world_says(browser, truth)
        assert near(pixel(browser, 4.5, 2.5), "site")  # the empty site's centre: no disc
        assert "a1" in browser.find_element(By.ID, "agents").text

        click_world(browser, 0.5, 0.5)  # the agent: its details
        wait_until(lambda: "a1 at (0.50, 0.50)" in browser.find_element(By.ID, "details").text,
                   what="the clicked agent's details")
        click_world(browser, 2.5, 0.5)  # the free brick, then "remove"
        wait_until(lambda: "brick at (2.5, 0.5)" in browser.find_element(By.ID, "disc").text,
                   what="the clicked disc")
        browser.find_element(By.ID, "remove").click()
        wait_until(lambda: near(pixel(browser, 2.5, 0.5), "blank"), what="the brick to vanish from the canvas")
        after = rw.world.view()
        assert (2.5, 0.5) not in set(zip(after.disc_xs, after.disc_ys))  # gone from the world itself
        wait_until(lambda: "done" in browser.find_element(By.ID, "perturbed").text, what="the page's 'done'")


def test_the_page_draws_each_cue_kind_with_a_mark_of_its_own_under_the_discs(bus, browser):
    # A site cue is a cross (through its cell's centre), a supply cue a diamond outline (its
    # centre left clear); a cue under a brick is hidden, as the agents' sensors miss it; the
    # legend names both kinds.
    from selenium.webdriver.common.by import By

    world = make(LAYOUT, cue_reach=5.0)
    world.attach("a1")
    for cell, kind in (((3, 1), "site"), ((5, 1), "supply"), ((4, 0), "site"), ((2, 2), "site")):
        world.cues.place(cell, kind)  # (3.5, 1.5); (5.5, 1.5); on the empty site (4.5, 2.5); under the brick (2.5, 0.5)
    with live_page(bus, browser, world):
        assert len(picture(browser)["cues"]) == 4
        assert near(pixel(browser, 3.5, 1.5), "cue_site") and near(pixel(browser, 4.5, 2.5), "cue_site")
        assert near(pixel(browser, 5.5, 1.5), "blank") and near(pixel(browser, 5.69, 1.69), "cue_supply")
        assert near(pixel(browser, 2.7, 0.7), "brick")  # the covered cue's cross arm: under the brick
        legend = browser.find_element(By.ID, "legend").text
        assert "site cue" in legend and "supply cue" in legend


def test_the_recording_page_scrubs_the_timeline(tmp_path, browser):
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By

    out = tmp_path / "r.mcap"
    views = [view(0, 0.5, filled=False), view(50, 3.5, filled=False), view(100, 5.25, filled=True)]
    with McapRecorder(out) as rec:
        for v in views:
            rec.add(keys.view("w0"), encode(v), v.tick)
    from conag.commands.view import load_timeline

    with ViewerServer(load_timeline(str(out))).serve_in_thread() as server:
        browser.get(server.url)
        wait_until(lambda: browser.execute_script("return window.viewer && window.viewer.frames > 0"),
                   what="the recording's first picture")
        check_drawn_where_the_world_says(browser, views[0])
        slider = browser.find_element(By.ID, "timeline")
        # A real click at the slider's right end: the last tick.
        ActionChains(browser).move_to_element_with_offset(slider, slider.size["width"] // 2 - 2, 0).click().perform()
        wait_until(lambda: picture(browser)["tick"] == 100, what="the picture of tick 100")
        check_drawn_where_the_world_says(browser, views[2])
        assert near(pixel(browser, 0.5, 0.5), "blank")  # the agent is no longer where it was
        browser.execute_script("window.viewer.seek(60)")  # between two views: the one before
        wait_until(lambda: picture(browser)["tick"] == 50, what="the picture of tick 50")
        check_drawn_where_the_world_says(browser, views[1])
        # From tick 50 to 0 only the agent moves: the walls, sites and discs are not painted
        # again (a browser on the run's cores pays for every stroke), yet the picture is right.
        paints = browser.execute_script("return window.viewer.sceneryPaints")
        browser.execute_script("window.viewer.seek(0)")
        wait_until(lambda: picture(browser)["tick"] == 0, what="the picture of tick 0")
        check_drawn_where_the_world_says(browser, views[0])
        assert near(pixel(browser, 3.5, 0.5), "blank")  # the agent of tick 50 is gone from the canvas
        assert browser.execute_script("return window.viewer.sceneryPaints") == paints


def test_a_recorded_fig19_build_opens_and_plays(tmp_path, browser):
    """`conag run --record --maps-every 10`, then `conag view FILE.mcap`: the final picture
    matches the recording's last view, the agent's maps show on a click, and playing the
    timeline moves through the ticks."""
    from selenium.webdriver.common.by import By

    rec = tmp_path / "r.mcap"
    env = dict(os.environ)
    run = subprocess.run([sys.executable, "-m", "conag", "run", str(SCENARIOS / "fig19.toml"), "--record", str(rec),
                          "--headless", "--quiet", "--maps-every", "10", "--listen", f"tcp/127.0.0.1:{_port()}"],
                         cwd=ROOT, capture_output=True, text=True, timeout=600, env=env)
    assert run.returncode == 0, run.stdout + run.stderr
    proc = subprocess.Popen([sys.executable, "-m", "conag", "view", str(rec), "--port", "0"], cwd=ROOT,
                            stdout=subprocess.PIPE, text=True)
    try:
        url = _read_url(proc)
        timeline = json.loads(_get(url + "api/timeline"))
        assert timeline["last"] > 0 and len(timeline["ticks"]) > 10
        browser.get(url)
        wait_until(lambda: browser.execute_script("return window.viewer && window.viewer.frames > 0"),
                   what="the recording's first picture")
        browser.execute_script(f"window.viewer.seek({timeline['last']})")
        wait_until(lambda: picture(browser)["tick"] == timeline["last"], what="the last picture")
        from conag.recording.mcap_log import read_recording
        from protocol import decode

        last = [e for e in read_recording(rec).entries if e.key.endswith("/view")][-1]
        v = decode(last.data)
        assert all(v.site_filled)
        check_drawn_where_the_world_says(browser, v)
        assert "COMPLETE" in browser.find_element(By.ID, "status").text or "21/21" in \
            browser.find_element(By.ID, "status").text
        browser.find_element(By.CSS_SELECTOR, "#agents tr.agent").click()  # a1: its details and maps
        wait_until(lambda: "behaviour" in browser.find_element(By.ID, "details").text, what="the details")
        wait_until(lambda: len(browser.find_elements(By.CSS_SELECTOR, "#maps canvas")) == 9, timeout=30,
                   what="a1's nine maps")  # seen to take over 10 s with both cores busy elsewhere
        maps = browser.execute_script("return window.viewer.maps")
        assert maps["tick"] <= timeline["last"] and maps["size"] == 41
        assert max(layer_cells(maps["layers"]["config"])) > 0  # the blueprint's sites on its configuration ESM
        shot = os.environ.get("CONAG_SCREENSHOT")
        if shot:
            browser.find_element(By.TAG_NAME, "body").screenshot(shot)
        browser.execute_script(f"window.viewer.seek({timeline['first']})")
        wait_until(lambda: picture(browser)["tick"] == timeline["first"], what="back to the first picture")
        browser.find_element(By.ID, "speed").send_keys("x50")
        browser.find_element(By.ID, "play").click()
        wait_until(lambda: picture(browser)["tick"] > timeline["first"] + 100, what="playing to move on")
    finally:
        proc.terminate()
        proc.wait(10)


def _port() -> int:
    from tests.conftest import free_port

    return free_port()


def _read_url(proc: subprocess.Popen) -> str:
    for line in proc.stdout:
        if line.startswith("viewer at "):
            return line.split()[-1]
    raise AssertionError(f"conag view printed no address (exit {proc.poll()})")


def _get(url: str) -> str:
    import urllib.request

    with urllib.request.urlopen(url, timeout=10) as r:
        return r.read().decode()


def test_conag_run_view_shows_the_build_live(browser):
    """`conag run --view PORT`: the page follows the run as it builds (ticks go on, sites
    fill) and draws each body and filled site where its pictures say."""
    from types import SimpleNamespace

    from tests.conftest import Process, free_port

    port = free_port()
    run = Process("run", str(SCENARIOS / "fig19.toml"), "--headless", "--view", str(port),
                  "--listen", f"tcp/127.0.0.1:{free_port()}")
    try:
        run.wait_for("viewer at ", timeout=30)
        browser.get(f"http://127.0.0.1:{port}/")
        wait_until(lambda: browser.execute_script("return window.viewer && window.viewer.mode") == "live",
                   what="the live page")
        first = wait_until(lambda: (p := picture(browser)) and p["tick"] > 0 and p["agents"] and p,
                           timeout=60, what="a ticking world on the page")
        later = wait_until(lambda: (p := picture(browser)) and p["sites_filled"] > first["sites_filled"] and p,
                           timeout=120, what="a site filled while watching")
        assert later["tick"] > first["tick"]
        browser.execute_script("window.viewer.frozen = true")  # nothing else to compare against meanwhile
        p = picture(browser)
        v = SimpleNamespace(site_xs=[s[0] for s in p["sites"]], site_ys=[s[1] for s in p["sites"]],
                            site_filled=[s[2] for s in p["sites"]], agent_ids=[a["id"] for a in p["agents"]],
                            agent_x=[a["x"] for a in p["agents"]], agent_y=[a["y"] for a in p["agents"]],
                            agent_heading=[a["heading"] for a in p["agents"]])
        check_drawn_where_the_world_says(browser, v)
    finally:
        run.stop(timeout=30)
