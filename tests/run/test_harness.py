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


def test_last_settings_that_are_no_dict_fail_the_method_saying_so():
    # a list failed it with dbench's own "AttributeError: 'list' object has no attribute
    # 'items'", which said nothing of what the method had done wrong
    from dbench.run.inputs import MethodError

    class Listing(_Sleepy):
        name = "listing"

        def denoise(self, data):
            self.last_settings = ["radius", 3]
            return np.array(data.color, np.float32)

    f = Frame(color=np.zeros((8, 8, 3)), reference=np.zeros((8, 8, 3)))
    with pytest.raises(MethodError, match="listing: last_settings is a list; expected a dict"):
        harness.run_cell(Listing(), f, metric_names=["rmse"], repeats=1)


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


class _Compiling(Denoiser):
    """A running mean whose first call without and first call with a history are slow, as a
    Numba method compiles its first-frame and its reprojection paths."""
    name = "compiling"
    kinds = {"sequence"}
    needs = {"color"}
    defaults = {}

    def __init__(self):
        super().__init__()
        self.calls, self.compiled, self.history = 0, set(), None

    def reset(self):
        self.history = None

    def denoise(self, data):
        self.calls += 1
        path = "first" if self.history is None else "reproject"
        if path not in self.compiled:
            self.compiled.add(path)
            time.sleep(0.3)
        c = np.asarray(data.color, np.float64)
        self.history = (c, 1) if self.history is None else (
            self.history[0] + c, self.history[1] + 1)
        return (self.history[0] / self.history[1]).astype(np.float32)


def test_a_sequence_shorter_than_the_warm_up_is_timed_without_compilation():
    """3 frames, all timed (no more than the 8-frame warm-up): frames 0 and 1 carried the
    compilation of accumulate (8.9 s and 4.8 s against 0.3 ms on frame 2 at 16², so time_s
    was 4.8 s) and svgf; the method now runs untimed over frames 0-1 and is reset first."""
    from dbench.synthetic import synthetic_sequence

    seq = synthetic_sequence(8, 8, frames=3)
    m = _Compiling()
    res = harness.run_sequence_cell(m, seq, metric_names=["rmse"])
    assert m.calls == 5 and len(res.times_s) == 3 and max(res.times_s) < 0.1
    # the warm-up's history is forgotten: the last output is the mean of the 3 frames
    expected = np.mean([np.asarray(f.color, np.float64) for f in seq], axis=0)
    np.testing.assert_allclose(res.output, expected, rtol=1e-6)
    assert res.sequence.per_frame[0]["rmse"] == pytest.approx(
        float(np.sqrt(np.mean((np.asarray(seq[0].color, np.float64)
                               - np.asarray(seq[0].reference, np.float64)) ** 2))), rel=1e-5)
    # a sequence longer than the warm-up times frames 8 on: no untimed pass before the run,
    # frames 0-1 once more after it (untimed, to compare the calls)
    m = _Compiling()
    res = harness.run_sequence_cell(m, synthetic_sequence(8, 8, frames=10), metric_names=["rmse"])
    assert m.calls == 12 and len(res.times_s) == 2


def test_a_sequence_shorter_than_the_warm_up_gets_its_temporal_stability():
    """Its metrics averaged all 3 frames while t_rmse and tpsnr were NaN (the report said "Not
    recorded: t_rmse, tpsnr"): they waited for frame 8. They now score the differences of the
    frames the metrics average, frames 1-2; a single frame has none."""
    from dbench.run.sequence_run import run_sequence, temporal_stability
    from dbench.synthetic import synthetic_sequence

    seq = synthetic_sequence(8, 8, frames=3)
    res = run_sequence("noisy", seq)
    outs = [np.asarray(f.color, np.float64) for f in seq]
    refs = [np.asarray(f.reference, np.float64) for f in seq]
    d = [(outs[i] - outs[i - 1]) - (refs[i] - refs[i - 1]) for i in (1, 2)]
    assert res.summary["t_rmse"] == pytest.approx(float(np.sqrt(np.mean(np.square(d)))),
                                                  rel=1e-6)
    assert 0 < res.summary["tpsnr"] < 100
    assert np.isnan(temporal_stability(outs[:1], refs[:1])["t_rmse"])
    # longer than the warm-up: from frame 8 on, as before
    long = synthetic_sequence(8, 8, frames=10)
    assert run_sequence("noisy", long).summary["t_rmse"] == pytest.approx(temporal_stability(
        [f.color for f in long][7:], [f.reference for f in long][7:], warmup=1)["t_rmse"])


@pytest.mark.parametrize("made", [lambda c: np.asarray(c).astype(object),
                                  lambda c: np.asarray(c).astype(str), lambda c: None,
                                  # radiance cut to whole numbers
                                  lambda c: np.asarray(c).astype(np.int32),
                                  lambda c: np.asarray(c) > 0.5])
def test_an_output_that_is_no_array_of_numbers_is_refused_naming_the_method(made):
    # an object array failed inside the metrics with NumPy's "ufunc 'isfinite' not supported
    # for the input types", which named neither the method nor its output
    from dbench.errors import DbenchInputError

    class Odd(_Sleepy):
        name = "odd-output"

        def denoise(self, data):
            return made(data.color)

    f = Frame(color=np.ones((8, 8, 3)), reference=np.ones((8, 8, 3)))
    with pytest.raises(DbenchInputError,
                       match=r"odd-output output: expected (floating-point|shape)"):
        harness.run_cell(Odd(), f, metric_names=["rmse"], repeats=1)


def test_a_method_never_sees_the_reference_it_is_scored_against():
    # the method's copy held data.reference: returning it scored a perfect 0 error, silently
    seen = {}

    class Peeks(_Sleepy):
        name = "peeks"

        def denoise(self, data):
            seen.update(reference=data.reference, reference_var=data.reference_var)
            return np.array(data.color, np.float32)

    f = Frame(color=np.ones((8, 8, 3)), reference=np.full((8, 8, 3), 2.0),
              reference_var=np.full((8, 8, 3), 0.1))
    res = harness.run_cell(Peeks(), f, metric_names=["rmse"], repeats=1)
    assert seen == {"reference": None, "reference_var": None}
    assert res.metrics["rmse"] == pytest.approx(1.0)  # still scored against the reference
    assert f.reference is not None and f.reference_var is not None  # the caller's frame keeps it


def test_a_method_cannot_declare_that_it_needs_the_reference():
    from dbench.denoiser import Denoiser, register

    cls = type("NeedsRef", (Denoiser,), {"needs": {"color", "reference"},
                                         "denoise": lambda self, data: data.reference})
    with pytest.raises(ValueError, match="needs the reference: it is what a method is scored"):
        register("needs-reference-test")(cls)
