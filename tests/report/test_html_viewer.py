"""The HTML viewer in a real browser (headless Chromium from file://): issue "an interactive
report". Pages come from real `dbench run`s at tiny sizes."""
from __future__ import annotations

import numpy as np
import pytest

from dbench.cli import main

pytestmark = pytest.mark.usefixtures("renderer")


def _run(tmp_path_factory, name: str, *args: str):
    out = tmp_path_factory.mktemp(name)
    cache = tmp_path_factory.getbasetemp() / "viewer-cache"
    assert main(["run", *args, "--ref-spp", "32", "--repeats", "1", "--quiet",
                 "--cache", str(cache), "--out", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def steady_run(tmp_path_factory):
    return _run(tmp_path_factory, "steady", "--method", "noisy,jbf,oidn", "--scene", "cornell",
                "--spp", "4", "--res", "32")


@pytest.fixture(scope="module")
def sequence_run(tmp_path_factory):
    return _run(tmp_path_factory, "sequence", "--method", "noisy,accumulate,jbf", "--scene",
                "flicker", "--spp", "1", "--res", "24x16", "--frames", "4")


@pytest.fixture(scope="module")
def transient_run(tmp_path_factory):
    return _run(tmp_path_factory, "transient", "--method", "noisy,gauss3d", "--scene",
                "cornell-transient", "--spp", "4", "--res", "16", "--bins", "12")


def _open(browser, folder):
    from selenium.webdriver.support.ui import WebDriverWait
    browser.get_log("performance")  # forget earlier pages' requests
    browser.get((folder / "index.html").as_uri())
    # the viewer inflates its images first (asynchronously), then marks the page ready
    WebDriverWait(browser, 20).until(lambda d: d.execute_script(
        "return !document.getElementById('main') || document.body.dataset.ready === '1'"))
    browser.execute_script("window.scrollTo(0, 0)")
    return browser.find_element("tag name", "body")


def _errors(browser) -> list:
    return [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]


def _pixel(browser, i: int, j: int) -> np.ndarray:
    """The main canvas's RGB at the centre of image pixel (row i, column j), whole-image
    view."""
    return np.array(browser.execute_script(
        "const c = document.getElementById('main'), D = window.DBENCH;"
        "const sx = c.width / D.width, sy = c.height / D.height;"
        "return Array.from(c.getContext('2d').getImageData("
        "  Math.floor((arguments[1] + 0.5) * sx), Math.floor((arguments[0] + 0.5) * sy), 1, 1"
        ").data).slice(0, 3);", int(i), int(j)), dtype=np.float64)


def _expected(image: np.ndarray, i: int, j: int, ev: float = 0.0) -> np.ndarray:
    from dbench.metrics import tonemap
    half = image[i, j].astype(np.float16).astype(np.float64)
    return 255.0 * tonemap(half, ev)


def test_half_float_packing_round_trips():
    """What the page decodes equals the image cast to float16 (NaN shown as 0, values beyond
    the half range clipped)."""
    from dbench.report.html import decode_half, encode_half
    rng = np.random.default_rng(0)
    img = (rng.lognormal(-1, 2, (7, 5, 3))).astype(np.float32)
    img[0, 0] = [np.nan, 1e6, -1e6]
    out = decode_half(encode_half(img), img.shape)
    expected = np.clip(np.nan_to_num(img, nan=0.0), -65504, 65504).astype(np.float16)
    np.testing.assert_array_equal(out, expected.astype(np.float32))


def test_run_page_shows_every_method_offline(browser, steady_run, requested_urls):
    body = _open(browser, steady_run)
    labels = [t.text.split(": ", 1)[-1] for t in browser.find_elements("css selector", ".thumb")]
    assert labels == ["noisy", "jbf", "oidn", "reference"]
    assert not _errors(browser)
    urls = requested_urls(browser)
    assert urls and all(u.startswith("file://") for u in urls), urls
    assert body.get_attribute("data-current") == "1"  # the first method is shown first
    table = browser.find_element("css selector", "table.metrics")
    assert [td.text for td in table.find_elements("css selector", "tbody td:first-child")] == \
        ["jbf", "noisy", "oidn"]


def test_keys_switch_to_the_pixels_of_method_k(browser, steady_run):
    from dbench import io
    images = {lab: io.read_exr(steady_run / "images" / f"{lab}.exr")["color"]
              for lab in ("noisy", "jbf", "oidn", "reference")}
    body = _open(browser, steady_run)
    body.send_keys("0")  # whole image
    diff = np.abs(images["jbf"] - images["noisy"]).mean(-1)
    i, j = np.unravel_index(int(np.argmax(np.where(images["noisy"].max(-1) < 0.8, diff, 0))),
                            diff.shape)
    for key, label in (("1", "noisy"), ("2", "jbf"), ("3", "oidn"), ("4", "reference")):
        body.send_keys(key)
        assert body.get_attribute("data-current") == str(int(key) - 1)
        np.testing.assert_allclose(_pixel(browser, i, j), _expected(images[label], i, j),
                                   atol=1.5, err_msg=label)
    body.send_keys("\ue012")  # arrow left: from the reference back to oidn
    assert body.get_attribute("data-current") == "2"
    browser.find_elements("css selector", ".thumb")[1].click()
    assert body.get_attribute("data-current") == "1"


def test_exposure_scales_linear_values_by_two_per_stop(browser, steady_run):
    from dbench import io
    from dbench.metrics.tonemapping import srgb_decode
    noisy = io.read_exr(steady_run / "images" / "noisy.exr")["color"]
    body = _open(browser, steady_run)
    body.send_keys("0")
    body.send_keys("1")
    lum = noisy.max(-1)
    i, j = np.unravel_index(int(np.argmin(np.abs(lum - 0.15))), lum.shape)  # unclipped at +1 EV
    before = srgb_decode(_pixel(browser, i, j) / 255.0)
    body.send_keys("++")  # two half stops
    assert browser.find_element("id", "exposure-value").text == "1 EV"
    after = srgb_decode(_pixel(browser, i, j) / 255.0)
    np.testing.assert_allclose(after, 2.0 * before, rtol=0.05, atol=2e-3)
    np.testing.assert_allclose(_pixel(browser, i, j), _expected(noisy, i, j, ev=1.0), atol=1.5)


def test_zoom_error_maps_split_and_sorting(browser, steady_run):
    body = _open(browser, steady_run)
    state = browser.execute_script("return window.dbenchViewer.state")
    assert state["scale"] > 1  # the worst window is pre-selected
    body.send_keys("0")
    main_canvas = browser.find_element("id", "main")
    from selenium.webdriver import ActionChains
    from selenium.webdriver.common.actions.wheel_input import ScrollOrigin
    ActionChains(browser).scroll_from_origin(ScrollOrigin.from_element(main_canvas, 0, 0),
                                             0, -100).perform()
    assert browser.execute_script("return window.dbenchViewer.state.scale") == pytest.approx(1.25)
    # drag pans every image: the view centre moves by the drag over the display scale
    cx = browser.execute_script("return window.dbenchViewer.state.cx")
    ActionChains(browser).move_to_element(main_canvas).click_and_hold().move_by_offset(
        40, 0).release().perform()
    moved = browser.execute_script("return window.dbenchViewer.state.cx")
    scale = browser.execute_script("return window.dbenchViewer.state.scale * "
                                   "document.getElementById('main').width / window.DBENCH.width")
    assert moved == pytest.approx(cx - 40 / scale, abs=0.05)
    body.send_keys("0")
    image = np.array([_pixel(browser, i, j) for i in range(0, 32, 4) for j in range(0, 32, 4)])
    browser.find_element("css selector", "input[name=mode][value=relative]").click()
    assert browser.execute_script("return window.dbenchViewer.state.mode") == "relative"
    errors = np.array([_pixel(browser, i, j) for i in range(0, 32, 4) for j in range(0, 32, 4)])
    assert not np.array_equal(image, errors)
    # split with the reference at the middle: the right half shows the reference's error (0)
    browser.find_element("id", "split").click()
    assert browser.execute_script("return window.dbenchViewer.state.split") is True
    np.testing.assert_allclose(_pixel(browser, 16, 28), [0, 0, 4], atol=1)
    header = browser.find_elements("css selector", "table.metrics th")
    col = [h.text for h in header].index("relmse")
    header[col].click()
    values = [float(td.text.split(" ")[0]) for td in browser.find_elements(
        "css selector", f"table.metrics tbody td:nth-child({col + 1})")]
    assert values == sorted(values)
    header[col].click()
    values = [float(td.text.split(" ")[0]) for td in browser.find_elements(
        "css selector", f"table.metrics tbody td:nth-child({col + 1})")]
    assert values == sorted(values, reverse=True)
    assert browser.find_elements("css selector", "table.metrics td.best")
    assert not _errors(browser)


def test_sequence_frame_player(browser, sequence_run):
    body = _open(browser, sequence_run)
    assert not _errors(browser)
    assert browser.find_element("id", "player").is_displayed()
    assert body.get_attribute("data-frame") == "3"  # the last frame first
    slider = browser.find_element("id", "frame")
    browser.execute_script("arguments[0].value = 0; arguments[0].dispatchEvent("
                           "new Event('input'))", slider)
    assert body.get_attribute("data-frame") == "0"
    assert browser.find_element("id", "frame-label").text == "frame 0"
    frames = browser.execute_script(
        "const v = window.dbenchViewer; return [0, 3].map(f => Array.from("
        "v.linear(v.state.current, f).slice(0, 300)))")
    assert frames[0] != frames[1]
    body.send_keys(".")
    assert body.get_attribute("data-frame") == "1"
    browser.find_element("id", "play").click()
    assert browser.find_element("id", "play").text == "pause"
    browser.find_element("id", "play").click()
    assert browser.find_element("id", "play").text == "play"
    assert browser.find_elements("css selector", ".plots img")


def test_transient_bin_slider(browser, transient_run):
    body = _open(browser, transient_run)
    assert not _errors(browser)
    labels = browser.execute_script("return window.DBENCH.frame_labels")
    assert len(labels) == 12 and labels[0].startswith("bin 0")
    slider = browser.find_element("id", "frame")
    browser.execute_script("arguments[0].value = 5; arguments[0].dispatchEvent("
                           "new Event('input'))", slider)
    assert body.get_attribute("data-frame") == "5"
    assert browser.find_element("id", "frame-label").text.startswith("bin 5")
    srcs = [img.get_attribute("src") for img in browser.find_elements("css selector",
                                                                       ".plots img")]
    assert any(s.endswith("streak.png") for s in srcs)


def test_sweep_page_sorts_the_grid(browser, tmp_path):
    """`dbench report`'s results/index.html: the grid of a sweep, sortable, offline."""
    import json
    from dbench.report.html import sweep_page
    from dbench import io
    sweep = tmp_path / "sweep"
    io.write_json(sweep / "sweep.json", {"config": {"spp": [4, 16], "res": 32}})
    for scene in ("a", "b"):
        for spp, scale in ((4, 1.0), (16, 0.5)):
            for method, value in (("noisy", 0.3), ("m1", 0.1), ("m2", 0.2)):
                v = value * scale * (2 if scene == "b" else 1)
                io.write_json(sweep / "cells" / scene / f"{spp:05d}spp" / f"{method}.json",
                              {"status": "ok", "scene": scene, "method": method, "spp": spp,
                               "res": 32, "relmse": v, "relmse_ci": 0.01, "rmse": v,
                               "time_s": 0.01})
    from dbench.run.sweep import load_cells
    sweep_page(tmp_path, [(sweep, load_cells(sweep))])
    _open(browser, tmp_path)
    assert not _errors(browser)
    header = browser.find_elements("css selector", "table.metrics th")
    assert [h.text for h in header] == ["scene", "method", "4 spp", "16 spp"]
    header[2].click()
    col = [td.text for td in browser.find_elements("css selector",
                                                    "table.metrics tbody td:nth-child(3)")]
    assert [float(t.split(" ")[0]) for t in col] == sorted(float(t.split(" ")[0]) for t in col)
    assert json.loads(json.dumps(browser.execute_script("return window.DBENCH.tables.length"))) == 1


def test_each_report_names_the_files_its_run_wrote(steady_run, sequence_run, transient_run):
    """The closing "Files:" line of report.md names files that are there (a ``<method>`` in a
    name stands for each method's), for every kind of run."""
    import re

    for run in (steady_run, sequence_run, transient_run):
        line = next(ln for ln in (run / "report.md").read_text().splitlines()
                    if ln.startswith("Files:"))
        names = re.findall(r"`([^`]+\.(?:csv|png))`", line)
        assert names, line
        missing = [n for n in names if not list(run.glob(re.sub(r"<\w+>", "*", n)))]
        assert missing == [], (run.name, missing)
