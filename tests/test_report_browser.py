"""The HTML report and comparison pages in a real browser (headless Chromium).

Needs Debian's ``chromium`` and ``chromium-driver`` (``/usr/bin/chromium``,
``/usr/bin/chromedriver``) and selenium (test extra). Without them the tests
skip locally; under CI (``CI`` set) a missing browser fails.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import time

import pytest

from sitframe.cli.app import main

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
DRIVER = shutil.which("chromedriver") or "/usr/bin/chromedriver"
FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--window-size=1300,1000")


def _missing() -> str | None:
    try:
        import selenium  # noqa: F401
    except ImportError:
        return "selenium is not installed (pip install -e '.[test]')"
    for path, pkg in ((CHROMIUM, "chromium"), (DRIVER, "chromium-driver")):
        if not os.access(path, os.X_OK):
            return f"{path} not found (apt-get install chromium chromium-driver; needs {pkg})"
    return None


@pytest.fixture(scope="module")
def browser():
    why = _missing()
    if why:
        if os.environ.get("CI"):
            pytest.fail(f"CI must test the report in a browser: {why}")
        pytest.skip(why)
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    os.environ.setdefault("SE_OFFLINE", "true")  # selenium must not look for drivers online
    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    for flag in FLAGS:
        opts.add_argument(flag)
    profile = tempfile.mkdtemp(prefix="sitframe-chromium-")
    opts.add_argument(f"--user-data-dir={profile}")
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(DRIVER), options=opts)
    yield driver
    driver.quit()
    shutil.rmtree(profile, ignore_errors=True)


def _open(driver, path) -> None:
    driver.get_log("browser")  # drop entries of earlier pages
    driver.get(path.resolve().as_uri())


def _errors(driver) -> list:
    return [e for e in driver.get_log("browser") if e["level"] == "SEVERE"]


def _wait(driver, script: str, timeout: float = 10.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        value = driver.execute_script(script)
        if value:
            return value
        time.sleep(0.05)
    raise AssertionError(f"timed out waiting for: {script}")


def _images(driver) -> list:
    return driver.execute_script(
        "return [...document.images].map(i => [i.getAttribute('src'), i.complete, "
        "i.naturalWidth])")


def _state(driver) -> tuple[str, str]:
    return driver.execute_script(
        "return [document.getElementById('replay-iter').textContent, "
        "document.getElementById('replay-world').toDataURL()]")


def test_report_page_loads_and_replay_plays_and_scrubs(browser, two_runs, tmp_path):
    a, _b = two_runs
    out = tmp_path / "rep"
    assert main(["analyse", str(a), "-o", str(out), "--dpi", "60"]) == 0
    _open(browser, out / "index.html")
    _wait(browser, "return document.getElementById('replay').dataset.ready === '1'")
    images = _images(browser)
    pngs = sorted(p.name for p in out.glob("*.png"))
    assert sorted(src for src, _c, _w in images) == pngs and len(pngs) >= 6
    assert all(done and width > 0 for _s, done, width in images), images

    it0, canvas0 = _state(browser)
    assert it0.startswith("0 / 299")
    browser.find_element("id", "replay-speed").send_keys("250")
    browser.find_element("id", "replay-play").click()
    _wait(browser, "return document.getElementById('replay-iter').textContent"
          ".split(' / ')[0] > 20")
    browser.find_element("id", "replay-play").click()  # pause
    it1, canvas1 = _state(browser)
    assert it1 != it0 and canvas1 != canvas0  # the robot moved on the canvas

    browser.execute_script("const s = document.getElementById('replay-slider'); s.value = 150;"
                           "s.dispatchEvent(new Event('input'))")
    it2, canvas2 = _state(browser)
    assert it2 == "150 / 299" and canvas2 not in (canvas0, canvas1)

    # an evaluation of another trial, chosen from the page
    browser.execute_script("const t = document.getElementById('replay-trial'); t.value = '1';"
                           "t.dispatchEvent(new Event('change'));"
                           "const e = document.getElementById('replay-episode');"
                           "e.selectedIndex = 1; e.dispatchEvent(new Event('change'))")
    assert _state(browser)[0] == "0 / 99"  # the 100-iteration evaluation in novel-1
    assert "novel-1" in browser.find_element("id", "replay-episode").text
    assert _errors(browser) == []


def test_compare_page_loads(browser, two_runs, tmp_path):
    a, b = two_runs
    out = tmp_path / "cmp"
    assert main(["compare", str(a), str(b), "-o", str(out)]) == 0
    _open(browser, out / "index.html")
    _wait(browser, "return document.readyState === 'complete'")
    images = _images(browser)
    assert [src for src, _c, _w in images] == ["metrics.png"]
    assert all(done and width > 0 for _s, done, width in images)
    rows = browser.execute_script(
        "return document.querySelectorAll('#comparison tbody tr').length")
    assert rows >= 5
    assert _errors(browser) == []
