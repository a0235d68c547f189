"""svgf's device path (_SVGFBase.denoise_device, dbench/methods/svgf/device.py) on CPU tensors:
Triton's interpreter runs the kernels the GPU compiles (dbench/methods/kernels/gpu/runtime.py),
and every frame must equal the host's numba backend."""
import numpy as np
import pytest
import torch

from dbench import registry
from dbench.device import download, upload
from dbench.errors import DbenchInputError
from device_checks import host_conversions_refused  # pytest puts this folder on sys.path

from test_accumulate import hard_sequence

pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")  # the interpreter's NaN lanes

# Device against the host's numba backend, 12×16, measured over the configurations below (and
# test_asvgf_device's): output max abs difference 1.3e-6 and max |Δ| / (|host| + 1e-3) 6.8e-6,
# both with normal_buffer="geo_normal", whose unnormalised normals make max(0, n·n')^128 turn
# one float32 ulp of the dot product (the host's fused arithmetic) into 128; without it at most
# 4.8e-7 and 7.8e-7. N and α: identical for svgf, 1.2e-7 for asvgf; status maps and NaN masks
# identical. The variance, against the image's largest: 3.4e-6 of it here; where a history holds
# about one frame m₂ − m₁² cancels, and in a 6-frame variant of rich_sequence one ulp of the
# host's fused multiply-add in the blend moved an emitter pixel's variance by 3.5e-4 of the
# largest (its output was unchanged), so the bound is 1e-3 of the largest.
RTOL, ATOL = 1e-4, 1e-5
VAR_OF_MAX = 1e-3


def rich_sequence(frames=5, fractional=False, seed=5):
    """hard_sequence (disocclusions, NaN/Inf colour, NaN motion) with more: an emission buffer
    with a lamp block (and NaN and negative values) on every frame but the fourth (the history
    layout changes and resets), a geometric normal with a NaN, a NaN and a zero albedo, and the
    light dimmed to 0.3 from the fourth frame on, with the re-shaded ``gradient`` samples dimmed
    alike (A-SVGF's gradient sees the change)."""
    rng = np.random.default_rng(seed)
    out = []
    for i, f in enumerate(hard_sequence(12, 16, frames=frames, fractional=fractional)):
        gn = f.normal + 0.1 * rng.standard_normal(f.normal.shape)
        gn /= np.linalg.norm(gn, axis=-1, keepdims=True)
        gn[3, 4] = np.nan
        color = f.color.copy()
        emission = None
        if i != 3:
            emission = np.zeros_like(color)
            emission[4:6, 10:13] = 5.0
            emission[0, 0] = np.nan
            emission[1, 1, 2] = -3.0
            color[4:6, 10:13] += 5.0
        scale = 1.0 if i < 3 else 0.3
        albedo = f.albedo.copy()
        albedo[7, 7] = np.nan
        albedo[8, 8] = 0.0
        out.append(f.with_buffers(color=color * scale, gradient=f.gradient * scale,
                                  geo_normal=gn.astype(np.float32), emission=emission,
                                  albedo=albedo))
    return out


def run_both(name, frames, **params):
    """Yields (host output, device output as NumPy, host method, device method) per frame."""
    host = registry.get(name, backend="numba", **params)
    dev = registry.get(name, **params)
    host.reset()
    dev.reset()
    for f in frames:
        oh = host.denoise(f)
        od = dev.denoise_device(upload(f, "cpu"))
        assert od.dtype == torch.float32 and tuple(od.shape) == oh.shape
        yield oh, download(od), host, dev


def assert_same(oh, od, host, dev):
    fin = np.isfinite(oh)
    np.testing.assert_array_equal(np.isfinite(od), fin)
    np.testing.assert_allclose(od[fin], oh[fin], rtol=RTOL, atol=ATOL)
    np.testing.assert_array_equal(dev.last["status"].numpy(), host.last["status"])
    np.testing.assert_allclose(dev.last["n"].numpy(), host.last["n"], rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(dev.last["alpha"].numpy(), host.last["alpha"], rtol=1e-6,
                               atol=1e-6)
    vh = host.last["variance"]
    np.testing.assert_allclose(dev.last["variance"].numpy(), vh, rtol=1e-4,
                               atol=VAR_OF_MAX * max(float(np.abs(vh).max()), 1e-12))


@pytest.mark.parametrize("params,rich,fractional", [
    ({}, False, True),
    (dict(preset="paper", iterations=2), False, False),  # feedback 0, Laplacian, no boost
    (dict(preset="falcor", iterations=2, taa=True), False, False),  # feedback 1, σ_l 10
    (dict(variance_boost="asvgf", iterations=0, sigma_n=64.0, albedo_floor=1.0), True, False),
    pytest.param(dict(normal_buffer="geo_normal", iterations=2, feedback_tap=4), True, False,
                 marks=pytest.mark.slow),  # the interpreter's 5 s; the default run has four
])
def test_device_equals_host_frame_by_frame(params, rich, fractional):
    seq = rich_sequence() if rich else hard_sequence(12, 16, frames=5, fractional=fractional)
    seen = set()
    for oh, od, host, dev in run_both("svgf", seq, **params):
        assert_same(oh, od, host, dev)
        seen |= set(np.unique(dev.last["status"].numpy()).tolist())
    assert seen == {0, 1, 2}


def test_hostile_inputs_give_finite_output_where_the_input_is_finite():
    frames = []
    for i, f in enumerate(rich_sequence()):
        c = f.color.copy()
        c[2:5, 3:7] = 3e38  # clamped to ±1e15: demodulated l² ≤ 1e36 stays finite
        c[9, 14] = -np.inf
        frames.append(f.with_buffers(color=c, motion=None if i == 2 else f.motion))
    for (oh, od, host, dev), f in zip(run_both("svgf", frames), frames):
        assert_same(oh, od, host, dev)
        fin_in = np.isfinite(f.color).all(-1)
        assert np.isfinite(od[fin_in]).all() and np.isfinite(oh[fin_in]).all()
        assert np.isfinite(dev.last["variance"].numpy()).all()


def test_reset_clears_the_device_history():
    seq = hard_sequence(12, 16, frames=3, fractional=False)
    dev = registry.get("svgf")
    dev.reset()
    for f in seq:
        dev.denoise_device(upload(f, "cpu"))
    dev.reset()
    again = download(dev.denoise_device(upload(seq[1], "cpu")))
    fresh = registry.get("svgf")
    fresh.reset()
    np.testing.assert_array_equal(again, download(fresh.denoise_device(upload(seq[1], "cpu"))))
    assert (dev.last["status"].numpy() == 0).all() and (dev.last["n"].numpy() <= 1).all()


def test_no_numpy_conversion_inside_a_call(monkeypatch):
    frames = [upload(f, "cpu") for f in rich_sequence(frames=3)]
    dev = registry.get("svgf", taa=True, normal_buffer="geo_normal")
    dev.reset()

    with host_conversions_refused(monkeypatch):
        for f in frames:
            dev.denoise_device(f)
    assert dev.last["n"].numpy().max() == 3


def test_device_path_declared_and_inputs_checked():
    cls = type(registry.get("svgf"))
    assert cls.device_backend == "triton" and cls.has_device_path()
    f = hard_sequence(4, 4, frames=1)[0]
    with pytest.raises(DbenchInputError, match="backend"):
        registry.get("svgf", backend="reference").denoise_device(upload(f, "cpu"))
    with pytest.raises(DbenchInputError, match="geo_normal"):
        registry.get("svgf", normal_buffer="geo_normal").denoise_device(upload(f, "cpu"))
    d = upload(f, "cpu")
    d.buffers["albedo"] = d.buffers["albedo"][:, :2]
    with pytest.raises(DbenchInputError, match="albedo"):
        registry.get("svgf").denoise_device(d)
