"""asvgf's device path on CPU tensors (Triton's interpreter): the gradient strata, their filter,
the adaptive history and the rest of SVGF equal the host's numba backend frame by frame
(dbench/methods/kernels/gpu/asvgf.py, dbench/methods/svgf/device.py)."""
import numpy as np
import pytest

from dbench import registry
from dbench.device import download, upload
from dbench.errors import DbenchInputError
from device_checks import host_conversions_refused  # pytest puts this folder on sys.path

from test_accumulate import hard_sequence
from test_asvgf import _dimmed
from test_svgf_device import assert_same, rich_sequence, run_both

pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")  # the interpreter's NaN lanes

# Measured against the host's numba backend (12×16, the sequences below): G (the gradient at
# full resolution) max abs difference 3e-7, α and N' 1.2e-7 (one float32 ulp: the host raises
# 1 − G to the 10th with pow, the kernels by squaring), the output 9.2e-7 (max |Δ| / (|host| +
# 1e-3) 6.3e-6, with normal_buffer="geo_normal"), the frame counts identical. The tolerances are
# test_svgf_device's (assert_same) and, for G, 1e-6 absolute.
G_ATOL = 1e-6


@pytest.mark.parametrize("params,seq", [
    ({}, "rich"),  # dbench preset: "gradient" boost (frame count), Gaussian w_l, α floor
    # two more gradient modes: marked slow (the interpreter takes 6-8 s each)
    pytest.param(dict(gradient_mode="filtered", normal_buffer="geo_normal"), "rich",
                 marks=pytest.mark.slow),
    pytest.param(dict(gradient_mode="filtered_abs", preset="paper", iterations=2), "rich",
                 marks=pytest.mark.slow),
    (dict(gradient_mode="paper", variance_boost="asvgf", alpha_floor=False, n_max=20.0,
          gradient_iterations=1, taa=True), "dimmed"),
])
def test_device_equals_host_frame_by_frame(params, seq):
    frames = rich_sequence(frames=5) if seq == "rich" else list(_dimmed(12, 16, 5, dim_at=3))
    g_max = 0.0
    for oh, od, host, dev in run_both("asvgf", frames, **params):
        assert_same(oh, od, host, dev)
        np.testing.assert_allclose(dev.last["gradient"].numpy(), host.last["gradient"],
                                   atol=G_ATOL)
        if host.last["frames"] is not None:
            np.testing.assert_array_equal(dev.last["frames"].numpy(), host.last["frames"])
        g_max = max(g_max, float(host.last["gradient"].max()))
    assert g_max > 0.2  # the light change was seen


def test_hostile_inputs_give_finite_output_where_the_input_is_finite():
    frames = []
    rng = np.random.default_rng(1)
    for i, f in enumerate(rich_sequence(frames=5)):
        c, g = f.color.copy(), f.gradient.copy()
        c[2:5, 3:7] = 3e38
        g[rng.random(g.shape[:2]) < 0.5] = np.nan  # only some pixels re-shaded
        g[0:3, 0:3] = 3e38
        g[6, 6, 1] = -np.inf
        frames.append(f.with_buffers(color=c, gradient=g,
                                     motion=None if i == 2 else f.motion))
    for (oh, od, host, dev), f in zip(run_both("asvgf", frames), frames):
        assert_same(oh, od, host, dev)
        np.testing.assert_allclose(dev.last["gradient"].numpy(), host.last["gradient"],
                                   atol=G_ATOL)
        fin_in = np.isfinite(f.color).all(-1)
        assert np.isfinite(od[fin_in]).all() and np.isfinite(oh[fin_in]).all()


def test_reset_clears_the_device_history_and_the_gradient():
    seq = list(_dimmed(12, 16, 3, dim_at=2))
    dev = registry.get("asvgf")
    dev.reset()
    g_max = 0.0
    for f in seq:
        dev.denoise_device(upload(f, "cpu"))
        g_max = max(g_max, float(dev.last["gradient"].numpy().max()))
    assert g_max > 0.2
    dev.reset()
    again = download(dev.denoise_device(upload(seq[2], "cpu")))
    fresh = registry.get("asvgf")
    fresh.reset()
    np.testing.assert_array_equal(again, download(fresh.denoise_device(upload(seq[2], "cpu"))))
    assert (dev.last["gradient"].numpy() == 0).all() and (dev.last["n"].numpy() <= 1).all()


def test_no_numpy_conversion_inside_a_call(monkeypatch):
    frames = [upload(f, "cpu") for f in rich_sequence(frames=3)]
    dev = registry.get("asvgf", taa=True, gradient_mode="filtered")
    dev.reset()

    with host_conversions_refused(monkeypatch):
        for f in frames:
            dev.denoise_device(f)
    assert dev.last["frames"].numpy().max() == 3


def test_a_missing_gradient_buffer_is_named_when_it_is_needed():
    seq = hard_sequence(6, 6, frames=2)
    dev = registry.get("asvgf")
    dev.reset()
    first = upload(seq[0], "cpu")
    del first.buffers["gradient"]
    dev.denoise_device(first)  # no previous frame: no gradient needed, as on the host
    second = upload(seq[1], "cpu")
    del second.buffers["gradient"]
    with pytest.raises(DbenchInputError, match="gradient"):
        dev.denoise_device(second)
