"""A headless Chromium (Debian's chromium + chromium-driver through Selenium), one per test
session; the tests skip with the reason where the browser is not installed."""
from __future__ import annotations

import json
import shutil

import pytest

CHROMIUM = ("/usr/bin/chromium", "/usr/bin/chromium-browser")
DRIVER = ("/usr/bin/chromedriver", "/usr/lib/chromium/chromedriver")


def _first(paths):
    for p in paths:
        if shutil.which(p):
            return p
    return None


@pytest.fixture(scope="session")
def browser():
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
    except ImportError as exc:  # pragma: no cover - setup installs it
        pytest.skip(f"selenium missing: {exc}")
    binary, driver = _first(CHROMIUM), _first(DRIVER)
    if binary is None or driver is None:  # pragma: no cover - setup installs them
        pytest.skip("chromium or chromedriver not installed (scripts/setup.sh installs them)")
    opts = webdriver.ChromeOptions()
    opts.binary_location = binary
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                "--window-size=1400,1000", "--disable-extensions"):
        opts.add_argument(arg)
    opts.set_capability("goog:loggingPrefs", {"performance": "ALL", "browser": "ALL"})
    d = webdriver.Chrome(service=Service(driver), options=opts)
    yield d
    d.quit()


@pytest.fixture()
def requested_urls():
    """A function: every URL a page asked for since the last call (Chrome's performance
    log)."""
    def urls_of(driver) -> list[str]:
        urls = []
        for entry in driver.get_log("performance"):
            msg = json.loads(entry["message"])["message"]
            if msg["method"] == "Network.requestWillBeSent":
                urls.append(msg["params"]["request"]["url"])
        return urls
    return urls_of
