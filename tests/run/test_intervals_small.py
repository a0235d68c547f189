"""One-seed intervals on small images (README.md, "Metrics"): the block bootstrap adapts its
block to the image and, with too few blocks, gives no interval (NaN, shown "± n/a") rather than
"± 0"; a missing interval never decides a ranking. Images of 64 px and more keep the 16-px
blocks and their intervals."""
import math

import numpy as np
import pandas as pd
import pytest
from scipy.ndimage import uniform_filter

from dbench.run import harness
from dbench.report import headline, refcompare, verdicts
from dbench.data import Frame
from dbench.metrics import judge as J
from denoisers import Blur  # tests/denoisers.py


def _pair(h, w=None, sigma=0.1, seed=0):
    rng = np.random.default_rng(seed)
    r = rng.random((h, w or h, 3)) + 0.5
    return r + rng.normal(0, sigma, r.shape), r


@pytest.mark.parametrize("h, w, side", [(256, 256, 16), (100, 100, 16), (64, 64, 16),
                                        (64, 48, 12), (48, 48, 12), (32, 32, 8), (24, 24, 6),
                                        (20, 20, 5), (16, 16, 4), (24, 16, 4), (15, 15, None),
                                        (12, 12, None), (8, 8, None), (16, 8, None)])
def test_block_side_follows_the_image(h, w, side):
    assert J.bootstrap_block(h, w) == side
    if side is not None:
        assert (h // side) * (w // side) >= J.BOOTSTRAP_MIN_BLOCKS
        assert side >= J.BOOTSTRAP_MIN_SIDE


@pytest.mark.parametrize("size", [8, 12, 16])
def test_small_images_get_a_nonzero_interval_or_none(size):
    o, r = _pair(size)
    j = J.judge(o, r)
    ci = J.bootstrap_interval([j], J.metric_names())
    for col, half in ci.items():
        assert math.isnan(half) or half > 0, (col, half)  # never "± 0"
    if size < 16:
        assert j.block is None and all(math.isnan(v) for v in ci.values())
    else:
        assert j.block == 4 and ci["rmse_ci"] > 0 and ci["relmse_ci"] > 0


def test_a_too_large_block_asked_for_gives_no_interval_rather_than_zero():
    o, r = _pair(16)
    ci = J.bootstrap_interval([J.judge(o, r, block=16)], ["rmse"])  # one block
    assert math.isnan(ci["rmse_ci"])


def test_surface_pixels_in_too_few_blocks_give_no_surface_interval():
    o, r = _pair(64)
    emitter = np.ones((64, 64, 1))
    emitter[:16, :32] = 0  # surface pixels in 2 of the 16 blocks
    ci = J.bootstrap_interval([J.judge(o, r, emitter=emitter)], ["rmse", "rmse_surface"])
    assert ci["rmse_ci"] > 0 and math.isnan(ci["rmse_surface_ci"])


@pytest.mark.parametrize("size", [64, 100, 128])
def test_images_of_64_px_and_more_keep_their_intervals(size):
    o, r = _pair(size, seed=3)
    emitter = np.zeros((size, size, 1))
    emitter[:3, :5] = 1.0
    cols = J.metric_names()
    now = J.bootstrap_interval([J.judge(o, r, emitter=emitter)], cols)
    before = J.bootstrap_interval([J.judge(o, r, emitter=emitter, block=16)], cols)
    assert now.keys() == before.keys()
    for c in now:
        assert now[c] == before[c] or (math.isnan(now[c]) and math.isnan(before[c])), c
    assert now["rmse_ci"] > 0


def test_bad_block_is_refused():
    o, r = _pair(16)
    for bad in (0, -4, 2.5, True):
        with pytest.raises(J.DbenchInputError, match="block"):
            J.judge(o, r, block=bad)


def test_four_px_blocks_cover_better_than_two_px_blocks_on_a_blurred_output():
    """Why the block is at least 4 px: a 5-px box filter correlates neighbouring pixels, and
    2-px blocks resampled as if independent give too narrow an interval."""
    rng = np.random.default_rng(1)
    t = uniform_filter(rng.random((16, 16, 3)), size=(5, 5, 1)) * 2 + 0.2
    sigma = 0.3 * t

    def output():
        return uniform_filter(t + rng.normal(0, 1, t.shape) * sigma, size=(5, 5, 1),
                              mode="reflect")

    truth = math.sqrt(np.mean([np.mean((output() - t) ** 2) for _ in range(2000)]))
    cover = {}
    for side in (2, 4):
        hits = 0
        for _ in range(200):
            j = J.judge(output(), t, names=["rmse"], block=side)
            hits += abs(j.values["rmse"] - truth) <= J.bootstrap_interval([j], ["rmse"])["rmse_ci"]
        cover[side] = hits / 200
    assert cover[4] > cover[2] + 0.05 and cover[4] >= 0.8, cover


def _frame(size):
    rng = np.random.default_rng(0)
    ref = rng.random((size, size, 3))
    return Frame(color=ref + rng.normal(0, 0.2, ref.shape), reference=ref,
                 reference_var=np.full(ref.shape, 1e-4), meta={"seed": 0})


@pytest.mark.parametrize("size", [8, 12, 16, 64])
def test_a_one_seed_cell_says_which_interval_it_has(size):
    res = harness.run_cell(Blur(), [_frame(size)], repeats=1)
    if size < 16:
        assert res.ci_kind.startswith("no interval") and "--seeds" in res.ci_kind
        assert math.isnan(res.metrics["rmse_ci"]) and math.isnan(res.metrics["relmse_ci"])
    else:
        assert f"({J.bootstrap_block(size, size)}-px blocks" in res.ci_kind
        assert res.metrics["rmse_ci"] > 0


def _cells(ci):
    """Two close methods and the noisy input, one seed each, with ``ci`` as every interval."""
    rows = []
    for method, rel in (("jbf", 0.03799), ("statistical", 0.03806), ("noisy", 0.1676)):
        rows.append({"status": "ok", "scene": "textured", "method": method, "spp": 4,
                     "res": 16, "n_seeds": 1, "seeds": [0], "ci_kind": "x", "relmse": rel,
                     "relmse_ci": ci, "rmse": rel, "rmse_ci": ci, "time_s": 0.01,
                     "time_s_iqr": 0.001, "per_seed": [{"seed": 0, "relmse": rel}]})
    from dbench.report import tables
    return tables.cells_frame(rows)


def test_a_missing_interval_never_declares_a_winner():
    d = _cells(float("nan"))
    rows = {r["method"]: r for _, r in d.iterrows()}
    assert verdicts.tie(rows["jbf"], rows["statistical"], "relmse") == "none"
    assert verdicts.tie(rows["jbf"], rows["noisy"], "relmse") == "none"
    line = verdicts.ranking_line(d, "relmse")
    assert " < " not in line and "(tied: no interval)" in line
    assert verdicts.marked(d, "relmse") == {"jbf", "statistical", "noisy"}
    table = headline.scene_table(d, verdicts.HEADLINE, "relmse").set_index("method")
    assert table.loc["jbf", "relmse"] == "**0.03799 ± n/a**"
    assert all("± 0 " not in v and not v.endswith("± 0") and not v.endswith("± 0**")
               for v in table["relmse"])
    assert refcompare._order(rows["jbf"], rows["statistical"], "relmse") == 0
    worse = d.copy()
    worse.loc[worse.method == "jbf", "relmse"] = 0.2  # above the noisy input's 0.1676
    assert headline.worse_than_noisy(worse, ["relmse"]) == {
        "jbf": "worse than noisy on relmse 1.2× (tied: no interval)"}


def test_real_intervals_still_rank():
    d = _cells(0.001)
    assert verdicts.ranking_line(d, "relmse") == (
        "relmse (lower is better): jbf = statistical (tied: intervals overlap) < noisy")


def test_fmt_value_says_when_there_is_no_interval():
    assert verdicts.fmt_value(0.5, float("nan")) == "0.5 ± n/a"
    assert verdicts.fmt_value(0.5, 0.01) == "0.5 ± 0.01"
    assert verdicts.fmt_value(float("nan"), float("nan")) == "—"


@pytest.mark.mitsuba
@pytest.mark.parametrize("res", [12, 16])
def test_run_reports_no_winner_without_an_interval(renderer, tmp_path, res):
    """The case of a one-seed run on a tiny image: jbf and statistical 0.07 % apart."""
    from dbench.cli import main

    out = tmp_path / "run"
    code = main(["run", "--method", "noisy,jbf,statistical", "--scene", "textured", "--spp",
                 "4", "--res", str(res), "--ref-spp", "64", "--repeats", "1", "--quiet",
                 "--cache", str(tmp_path / "cache"), "--out", str(out)])
    assert code == 0
    report = (out / "report.md").read_text()
    ranking = next(line for line in report.splitlines() if line.startswith("Ranking by"))
    assert "jbf < statistical" not in ranking and "statistical < jbf" not in ranking
    table = pd.read_csv(out / "metrics.csv")
    for col in [c for c in table.columns if c.endswith("_ci") and c != "time_s_ci"]:
        assert not (table[col] == 0).any(), col
    if res == 12:
        assert "± n/a" in report and "no interval" in ranking
        assert table["ci_kind"].str.startswith("no interval").all()
        assert table["relmse_ci"].isna().all()
    else:
        assert "4-px blocks" in report and (table["relmse_ci"] > 0).all()
