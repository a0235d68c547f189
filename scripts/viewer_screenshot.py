"""Screenshot of a run's HTML viewer in headless Chromium: the worst window of the first
method, split against the reference, with its relative-error map beside it in the thumbnails.

    python scripts/viewer_screenshot.py results/demo/run-cornell results/viewer.png
"""
from __future__ import annotations

import sys
from pathlib import Path

from selenium import webdriver
from selenium.webdriver.chrome.service import Service


def main(run: str, out: str) -> None:
    opts = webdriver.ChromeOptions()
    opts.binary_location = "/usr/bin/chromium"
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                "--window-size=1400,1100"):
        opts.add_argument(arg)
    driver = webdriver.Chrome(service=Service("/usr/bin/chromedriver"), options=opts)
    try:
        driver.get((Path(run).resolve() / "index.html").as_uri())
        driver.find_element("id", "split").click()
        driver.execute_script("window.dbenchViewer.state.splitAt = 0.5; "
                              "window.dbenchViewer.draw(); window.scrollTo(0, 0)")
        driver.save_screenshot(out)
    finally:
        driver.quit()
    print(f"written: {out}")


if __name__ == "__main__":
    main(*sys.argv[1:3])
