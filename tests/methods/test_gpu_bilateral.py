"""The Triton window kernel of ``jbf`` and ``statistical`` (docs/gpu.md §2), run through Triton's
interpreter on CPU tensors (the source the GPU compiles), against the float64 readable references.

Tolerance: max relative difference 1e-5 (float32 weights and sums, each pixel's whole window;
measured ≈ 3e-7 on these frames, as the Numba path's ≈ 2e-7). The device path must also convert
nothing to NumPy inside a call, and give finite output where the host path does (a block of
3e38 colour, NaN pixels, non-finite G-buffers and statistics).
"""
from __future__ import annotations

import numpy as np
import pytest
import torch

from dbench.data import Frame, SampleStats
from dbench.device import download, upload
from dbench.errors import DbenchInputError
from dbench.registry import get
from device_checks import host_conversions_refused  # pytest puts this folder on sys.path

from test_jbf import random_gbuffers, rel_err  # pytest puts this folder on sys.path

TOL = 1e-5


def frame(h=10, w=37, seed=0, spp=16, uniform_n=True):
    """A frame with background pixels, repeated G-buffer values and statistics; the width is not
    a multiple of the kernel's 32-px tile, so partial tiles are covered."""
    color, albedo, normal, depth, position = random_gbuffers(h, w, seed)
    rng = np.random.default_rng(seed + 1)
    y = rng.normal(color[..., None], 0.3, size=(h, w, 3, spp))
    n = np.full((h, w, 3), float(spp))
    if not uniform_n:
        n = rng.integers(2, spp + 1, size=(h, w, 3)).astype(float)
    st = SampleStats(n=n, mean=y.mean(-1), var_mean=y.var(-1, ddof=1) / n,
                     m3=((y - y.mean(-1, keepdims=True)) ** 3).mean(-1), transform="identity")
    return Frame(color=y.mean(-1), albedo=albedo, normal=normal, depth=depth, position=position,
                 stats=st)


def device_out(method, f):
    return download(method.denoise_device(upload(f, "cpu")))


@pytest.mark.parametrize("kw", [dict(radius=3), dict(radius=2, window="disk"),
                                dict(radius=3, features=("xy", "albedo", "normal", "depth")),
                                dict(radius=2, features=("albedo",)), dict(radius=2, hit_mask=False),
                                dict(radius=1, sigma_convention="sd")])
def test_jbf_device_equals_reference(kw):
    f = frame()
    ref = get("jbf", backend="reference", **kw).denoise(f)
    m = get("jbf", **kw)
    assert m.runs_on_device()
    assert rel_err(device_out(m, f), ref) < TOL
    assert m.last_settings["backend"] == "triton"


@pytest.mark.parametrize("kw, uniform", [(dict(radius=3), True), (dict(radius=3), False),
                                         (dict(radius=2, gamma=0.05), False),
                                         (dict(radius=2, membership=False), True),
                                         (dict(radius=2, window="disk", alpha=0.05), True)])
def test_statistical_device_equals_reference(kw, uniform):
    f = frame(uniform_n=uniform, seed=3)
    ref_m = get("statistical", backend="reference", **kw)
    ref = ref_m.denoise(f)
    m = get("statistical", **kw)
    assert rel_err(device_out(m, f), ref) < TOL
    for key in ("gamma_t", "nu", "uniform_n", "threshold_source", "n_bad_stats"):
        assert m.last_settings[key] == ref_m.last_settings[key], key


@pytest.mark.parametrize("membership", [True, False])
def test_statistical_device_gives_lights_their_own_label_as_the_host(membership):
    """An ``emitter`` buffer labels the lights in the device guide as in the host's (the
    base filter is jbf's, docs/methods/statistical.md §7)."""
    f = frame(seed=5)
    emitter = np.zeros(f.shape + (1,))
    emitter[2:6, 10:20] = 1.0
    f = f.with_buffers(emitter=emitter, color=f.color + 30.0 * emitter)
    ref = get("statistical", backend="reference", radius=3, membership=membership).denoise(f)
    blended = get("statistical", backend="reference", radius=3, membership=membership).denoise(
        f.with_buffers(emitter=None))
    assert rel_err(blended, ref) > 10 * TOL  # the buffer changes the result
    assert rel_err(device_out(get("statistical", radius=3, membership=membership), f), ref) < TOL


def test_hostile_inputs_are_finite_and_follow_the_policies():
    f = frame(h=12, w=20, seed=5)
    color = np.array(f.color)
    color[:4, :5] = 3e38                       # huge but finite: planes rescaled exactly
    color[6, 7] = np.nan                       # missing: no weight, filtered by neighbours
    albedo = np.array(f.albedo)
    albedo[8, 3] = np.inf                      # isolated: own colour
    mean = np.array(f.stats.mean)
    mean[2, 15] = np.nan                       # non-finite statistics: isolated
    st = SampleStats(n=f.stats.n, mean=mean, var_mean=f.stats.var_mean, m3=f.stats.m3,
                     transform="identity")
    f = f.with_buffers(color=color, albedo=albedo, stats=st)
    for name in ("jbf", "statistical"):
        ref = get(name, radius=2, backend="reference").denoise(f)
        out = device_out(get(name, radius=2), f)
        assert np.isfinite(out).all() and np.isfinite(ref).all()
        assert rel_err(out, ref) < TOL


def test_no_numpy_inside_a_device_call(monkeypatch):
    f = frame(h=6, w=9)
    for name in ("jbf", "statistical"):
        m = get(name, radius=1)
        data = upload(f, "cpu")

        with host_conversions_refused(monkeypatch, ("numpy", "__array__")):
            out = m.denoise_device(data)
        assert isinstance(out, torch.Tensor) and out.shape == (6, 9, 3)


def test_device_path_refusals_name_the_problem():
    f = frame(h=6, w=8)
    with pytest.raises(DbenchInputError, match="stats"):
        get("statistical", radius=1).denoise_device(upload(f.with_buffers(stats=None), "cpu"))
    neg = SampleStats(n=f.stats.n, mean=f.stats.mean, var_mean=-np.abs(f.stats.var_mean) - 1,
                      m3=f.stats.m3, transform="identity")
    data = upload(f, "cpu")
    data.stats.var_mean = upload(f.with_buffers(stats=neg), "cpu").stats.var_mean
    with pytest.raises(DbenchInputError, match="var_mean"):
        get("statistical", radius=1).denoise_device(data)
    m = get("jbf", mode="illumination")
    assert not m.runs_on_device()
    with pytest.raises(DbenchInputError, match="mode"):
        m.denoise_device(upload(f, "cpu"))


def test_welch_threshold_is_compared_in_float64():
    """γ = 0.3 gives γ_t² = 2/3, whose float32 rounding is larger: a pair whose d² lies between
    γ_t²·S and float32(γ_t²)·S fails the float64 test (each pixel keeps its own colour, as on
    the host) but would pass against a threshold rounded to float32."""
    g2 = 1.0 / (2.0 * 0.3) - 1.0
    g2_32 = float(np.float32(g2))
    assert g2_32 > g2
    s = 2.0                                   # Var(θ̂) = 1 at both pixels
    d = np.sqrt(s * 0.5 * (g2 + g2_32))
    assert g2 * s < d * d < g2_32 * s
    mean = np.zeros((1, 2, 3))
    mean[0, 0] = 1.0 + d
    mean[0, 1] = 1.0
    st = SampleStats(n=np.full((1, 2, 3), 16.0), mean=mean, var_mean=np.ones((1, 2, 3)),
                     m3=np.zeros((1, 2, 3)), transform="identity")
    normal = np.zeros((1, 2, 3))
    normal[..., 2] = 1.0
    f = Frame(color=mean, albedo=np.full((1, 2, 3), 0.5), normal=normal,
              depth=np.ones((1, 2, 1)), stats=st)
    host = get("statistical", radius=1, gamma=0.3, backend="numba").denoise(f)
    np.testing.assert_array_equal(host, mean.astype(np.float32))
    out = device_out(get("statistical", radius=1, gamma=0.3), f)
    np.testing.assert_array_equal(out, host)


def test_welch_threshold_reaches_the_kernel_as_float64(monkeypatch):
    """Triton compiles a float argument as float32 (the interpreter above keeps it a Python
    float, so only the launch arguments show it): γ_t² must reach the kernel in a float64
    tensor, unrounded, and not as a float argument."""
    import triton

    from dbench.methods.kernels.gpu import bilateral

    g2 = 1.0 / (2.0 * 0.3) - 1.0
    assert triton.runtime.jit.mangle_type(g2) == "fp32"
    seen = []
    real = bilateral.window_kernel

    class Recorder:
        def __getitem__(self, grid):
            def launch(*args, **meta):
                seen.append(args)
                return real[grid](*args, **meta)
            return launch

    monkeypatch.setattr(bilateral, "window_kernel", Recorder())
    device_out(get("statistical", radius=1, gamma=0.3), frame(h=4, w=5))
    (args,) = seen
    assert not any(isinstance(a, float) and a == g2 for a in args)
    assert any(isinstance(a, torch.Tensor) and a.dtype == torch.float64 and a.numel() == 1
               and a.item() == g2 for a in args)
