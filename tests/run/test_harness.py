"""Timing harness and convergence sanity (docs/metrics.md §6 checks 7 and 8)."""
import time

import numpy as np
import pytest

from dbench.run import harness
from dbench.report import tables
from dbench.data import Frame
from dbench.registry import Denoiser


class _Sleepy(Denoiser):
    name = "sleepy"
    kinds = {"steady"}
    needs = {"color"}
    defaults = {}

    def __init__(self):
        super().__init__()
        self.calls = 0

    def denoise(self, data):
        self.calls += 1
        if self.calls == 1:
            time.sleep(0.2)  # a slow first call (compilation) must not be reported
        return data.color.copy()


def test_noop_is_under_a_millisecond_and_median_of_five_is_reported():
    f = Frame(color=np.zeros((8, 8, 3)), reference=np.zeros((8, 8, 3)))
    m = _Sleepy()
    res = harness.run_cell(m, f, metric_names=["rmse"], repeats=5)
    assert m.calls == 6 and len(res.times_s) == 5
    assert res.time_s < 1e-3 and res.time_s == np.median(res.times_s)
    assert res.metrics["rmse"] == 0.0 and res.metrics["rmse_surface"] == 0.0


def test_cell_is_skipped_with_reason_when_buffers_are_missing():
    from dbench import registry
    res = harness.run_cell(registry.get("oidn"), Frame(color=np.zeros((4, 4, 3))))
    assert res.output is None and "albedo" in res.skipped


class _Resolving(Denoiser):
    """Records what it resolved, including values a cell file cannot hold."""
    name = "resolving"
    kinds = {"steady"}
    needs = {"color"}
    defaults = {"radius": "auto"}

    def denoise(self, data):
        self.last_settings = {"radius": np.int64(3), "source": "auto", "gain": np.float32(0.5),
                              "features": ("xy", "albedo"), "weights": np.ones((4, 4)),
                              "nested": {"a": 1}}
        return data.color.copy()


def test_cell_records_the_resolved_settings_as_plain_scalars():
    f = Frame(color=np.zeros((8, 8, 3)), reference=np.zeros((8, 8, 3)))
    res = harness.run_cell(_Resolving(), f, metric_names=["rmse"], repeats=1)
    assert res.settings == {"radius": 3, "source": "auto", "gain": 0.5,
                            "features": ["xy", "albedo"]}
    assert type(res.settings["radius"]) is int and res.params == {"radius": "auto"}
    assert harness.run_cell(_Sleepy(), f, metric_names=["rmse"], repeats=1).settings == {}


@pytest.mark.mitsuba
def test_noisy_rmse_converges_like_inverse_sqrt_spp(renderer, tmp_cache):
    from dbench import datasets
    rows = []
    for spp in (4, 16, 64, 256):
        f = datasets.load("cornell", spp=spp, res=24, needs={"reference"}, ref_spp=4096,
                          cache=tmp_cache, progress=False)
        rmse = float(np.sqrt(((f.color - f.reference) ** 2).mean()))
        rows.append({"scene": "cornell", "method": "noisy", "spp": spp, "rmse": rmse})
    import pandas as pd
    a, b = tables.noisy_fit(pd.DataFrame(rows), "cornell")
    assert -0.65 < b < -0.35


def test_zoom_window_finds_where_outputs_go_wrong():
    from dbench.report.run_report import zoom_window

    ref = np.full((40, 60, 3), 0.3, np.float32)
    out = ref.copy()
    out[30:34, 8:12] = 0.9                     # the only error: a 4×4 patch
    y0, x0, size = zoom_window(ref, [out])
    assert size == 10
    assert y0 <= 30 and y0 + size >= 34 and x0 <= 8 and x0 + size >= 12
    assert 0 <= y0 <= 40 - size and 0 <= x0 <= 60 - size
    # without outputs: the window with the most detail in the reference
    ref2 = ref.copy()
    ref2[2:8, 45:55] = np.random.default_rng(0).random((6, 10, 3))
    y0, x0, size = zoom_window(ref2)
    assert y0 <= 2 + 3 and x0 + size >= 48 and x0 <= 52


def _frame(h=8, w=8, seed=0):
    rng = np.random.default_rng(seed)
    ref = rng.uniform(0.1, 1.0, (h, w, 3)).astype(np.float32)
    return Frame(color=(ref + rng.normal(0, 0.05, ref.shape)).astype(np.float32),
                 reference=ref)


@pytest.mark.parametrize("args, kw, said", [
    (("jbf", [_frame()]), {}, "method: expected a built method"),
    ((None, []), {}, "frame: expected a frame or a non-empty list"),
    ((None, [_frame(8, 8), _frame(4, 4)]), {}, "frame: the frames of one cell"),
    ((None, [_frame(seed=0), _frame(seed=1)]), {}, "frame: the frames of one cell"),
    ((None, [_frame()]), {"metric_names": ["bogus"]}, "metric_names: expected a list of judged"),
    ((None, [_frame()]), {"metric_names": "rmse"}, "metric_names: expected a list of judged"),
    ((None, [_frame()]), {"repeats": 0}, "repeats: expected an integer >= 1"),
    ((None, [_frame()]), {"repeats": 1.5}, "repeats: expected an integer >= 1"),
    ((None, [_frame()]), {"warmup": -1}, "warmup: expected an integer >= 0"),
])
def test_run_cell_refuses_what_it_would_coerce_or_drop(args, kw, said):
    """Unknown metric names were dropped (a cell with no metrics), repeats 0 became 1, frames
    of two sizes or references were pooled, a method's name raised AttributeError."""
    from dbench.errors import DbenchInputError

    method = args[0] if args[0] is not None else _Sleepy()
    with pytest.raises(DbenchInputError, match=said):
        harness.run_cell(method, args[1], **kw)
