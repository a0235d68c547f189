"""The transient statistical denoiser's device path (docs/gpu.md §2;
dbench/methods/statistical/transient_device.py, the kernel dbench/methods/kernels/gpu/window3d.py)
on CPU tensors: Triton's interpreter runs the kernel the GPU compiles, and every output must
equal the host's Numba path (the one the harness runs without a GPU).

Tolerance: max relative difference 1e-5 (|Δ| / max(|host|, 1e-3)): float32 weights summed over
each voxel's whole window in one accumulator, against the host's symmetric half window summed in
float32 bands and merged in float64; measured ≤ 5.3e-7 on these videos (sparse samples, voxels of
zero variance, empty bins, background pixels, non-uniform n). Non-finite inputs must give the
host's non-finite mask and the host's isolation of bad statistics; wrong shapes are refused
naming the buffer; nothing is converted to NumPy inside a call.
"""
from __future__ import annotations

import numpy as np
import pytest
import torch

from dbench.data import SampleStats, TransientFrame
from dbench.device import download, upload
from dbench.errors import DbenchInputError
from dbench.registry import get
from device_checks import host_conversions_refused  # pytest puts this folder on sys.path

from test_statistical_transient import synthetic_video  # the same folder

pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")  # the interpreter's NaN lanes

TOL = 1e-5


def rel_err(a, b):
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    ok = np.isfinite(a) & np.isfinite(b)
    assert np.array_equal(np.isfinite(a), np.isfinite(b)), "non-finite masks differ"
    return float(np.max(np.abs(a[ok] - b[ok]) / np.maximum(np.abs(b[ok]), 1e-3)))


def video(h=6, w=9, t=5, seed=0, nonuniform=False, transform="identity", gbuffers=True,
          meta=None, scalar_n=False):
    """A tiny TransientFrame of sparse samples (synthetic_video: zero-variance voxels, an empty
    first bin, background pixels) with its total's variance; ``scalar_n``: one count for every
    voxel, as a float (the benchmark's videos)."""
    color, st, albedo, normal, depth = synthetic_video(h, w, t, seed=seed, empty=(0,),
                                                       nonuniform=nonuniform)
    stats = SampleStats(n=16.0 if scalar_n else st.n, mean=st.mean, var_mean=st.var_mean, m3=st.m3,
                        transform=transform, lam=0.5)
    kw = dict(albedo=albedo, normal=normal, depth=depth) if gbuffers else {}
    return TransientFrame(color=color.astype(np.float32), stats=stats,
                          total_var=st.var_mean.sum(axis=2), meta=meta or {}, **kw)


def both(f, **params):
    """(host numba output, device output as NumPy, host method, device method)."""
    host = get("statistical", backend="numba", **params)
    dev = get("statistical", **params)
    assert dev.runs_on_device() and dev.has_device_path()
    out = dev.denoise_device(upload(f, "cpu"))
    assert isinstance(out, torch.Tensor) and out.dtype == torch.float32
    return host.denoise(f), download(out), host, dev


SETTINGS = ("gamma_t", "nu", "uniform_n", "threshold_source", "n_bad_stats", "nonempty_bins",
            "bins_in_play", "window_voxels", "base", "radius_t", "temporal_profile", "shrink",
            "mass", "membership", "transform")


@pytest.mark.parametrize("params, frame_kw", [
    (dict(radius=1), dict(meta={"bin_width_opl": 0.01, "units": "m"})),   # r_t auto = 2
    (dict(radius=2, radius_t=1), {}),
    (dict(radius=1, radius_t=1, alpha=0.05), dict(nonuniform=True)),       # γ_t² table
    (dict(radius=1, radius_t=1, alpha=0.05), {}),                          # one γ_t
    (dict(radius=1, radius_t=2, base="gauss3d"), dict(gbuffers=False)),    # media
    (dict(radius=2, radius_t=1, window="disk", temporal_profile="gaussian", sigma_t=0.5), {}),
    (dict(radius=1, radius_t=1, shrink=False, mass=False, gamma=0.05), {}),  # the seed's rule
    (dict(radius=1, radius_t=1, membership=False), {}),
    (dict(radius=1, radius_t=1, skip_empty=False), {}),
    (dict(radius=1, radius_t=1), dict(transform="yeo-johnson")),           # θ̄ plane (7 planes)
])
def test_device_equals_host(params, frame_kw):
    oh, od, host, dev = both(video(**frame_kw), **params)
    assert rel_err(od, oh) < TOL
    assert dev.last_settings["backend"] == "triton"
    for key in SETTINGS:
        assert dev.last_settings[key] == host.last_settings[key], key
    if host.last_settings["mass"] == "on":
        assert float(dev.last_settings["mass_beta_mean"]) == pytest.approx(
            host.last_settings["mass_beta_mean"], rel=1e-6)


def test_device_equals_readable_reference():
    f = video(seed=2, nonuniform=True)
    ref = get("statistical", backend="reference", radius=1, radius_t=1, alpha=0.01).denoise(f)
    _, od, _, _ = both(f, radius=1, radius_t=1, alpha=0.01)
    assert rel_err(od, ref) < TOL


def hostile_video():
    f = video(7, 8, 5, seed=4)
    color = f.color.copy()
    color[3, 4, 2, 1] = np.nan                 # missing colour voxel: no weight
    color[5, 6, 3] = np.inf
    color[1, 1, 4] = 3e38                      # huge but finite
    mean = np.array(f.stats.mean)
    mean[2, 2, 3, 0] = np.nan                  # bad statistics: isolated voxel
    var = np.array(f.stats.var_mean)
    var[6, 1, 2, 2] = np.inf
    albedo = np.array(f.albedo)
    albedo[4, 0] = np.inf                      # isolated pixel (its own bins still mix)
    st = SampleStats(n=f.stats.n, mean=mean, var_mean=var, m3=f.stats.m3,
                     transform="identity", lam=0.5)
    return f.with_buffers(color=color, stats=st, albedo=albedo)


@pytest.mark.parametrize("params", [dict(radius=1, radius_t=1),
                                    dict(radius=1, radius_t=1, membership=False),
                                    dict(radius=1, radius_t=1, mass=False, shrink=False)])
def test_non_finite_inputs_follow_the_host(params):
    f = hostile_video()
    oh, od, host, dev = both(f, **params)
    assert rel_err(od, oh) < TOL
    assert dev.last_settings["n_bad_stats"] == host.last_settings["n_bad_stats"] == 2
    if not params.get("mass", True):
        # a voxel with bad statistics is nobody's neighbour: its output is its own colour
        np.testing.assert_allclose(od[2, 2, 3], f.color[2, 2, 3], rtol=1e-6)
        np.testing.assert_allclose(od[6, 1, 2], f.color[6, 1, 2], rtol=1e-6)


@pytest.mark.parametrize("params", [dict(radius=1, radius_t=1),
                                    dict(radius=1, radius_t=1, mass=False, shrink=False),
                                    dict(radius=1, radius_t=1, membership=False)])
def test_bright_block_is_finite_and_follows_the_host(params):
    """A block of colours near the float32 maximum mixes with its neighbours (its statistics
    are ordinary): the planes enter the float32 sums divided by a power of two and the epilogue
    multiplies them back, as on the host."""
    f = video(6, 9, 5, seed=3)
    color = f.color.copy()
    color[1:4, 2:6, 1:4] = 3e38
    oh, od, host, dev = both(f.with_buffers(color=color), **params)
    assert np.isfinite(oh).all() and np.isfinite(od).all()
    assert od.max() > 1e38
    assert rel_err(od, oh) < TOL


@pytest.mark.parametrize("make", [
    lambda: video(4, 5, 1),                                          # T = 1
    lambda: video(1, 1, 4),                                          # one pixel
    lambda: video(4, 5, 3).with_buffers(color=np.zeros((4, 5, 3, 3), np.float32)),  # all empty
    lambda: video(4, 5, 3).with_buffers(total_var=None),             # no pixel-total rule
    lambda: video(4, 5, 3, scalar_n=True),                           # a 0-d count
])
def test_small_and_empty_videos(make):
    oh, od, host, dev = both(make(), radius=1, radius_t=1)
    assert rel_err(od, oh) < TOL if oh.size else True
    assert dev.last_settings["mass"] == host.last_settings["mass"]


def test_wrong_shapes_are_refused_naming_the_buffer():
    f = video(4, 5, 3)
    m = get("statistical", radius=1, radius_t=1)

    def refused(name, **replace):
        data = upload(f, "cpu")
        for key, value in replace.items():
            if key == "total_var":
                data.total_var = value
            elif key.startswith("stats."):
                setattr(data.stats, key[6:], value)
            else:
                data.buffers[key] = value
        with pytest.raises(DbenchInputError, match=name):
            m.denoise_device(data)

    refused("stats.mean", **{"stats.mean": torch.zeros(4, 5, 2, 3, dtype=torch.float64)})
    refused("stats.n", **{"stats.n": torch.ones(4, 5, 3, dtype=torch.float64)})
    refused("albedo", albedo=torch.zeros(4, 4, 3))
    refused("total_var", total_var=torch.zeros(4, 5, 3, 3, dtype=torch.float64))
    refused("color", color=torch.zeros(4, 5, 3, 2))
    with pytest.raises(DbenchInputError, match="stats"):
        m.denoise_device(upload(f.with_buffers(stats=None), "cpu"))
    data = upload(f, "cpu")
    data.stats.var_mean = data.stats.var_mean.clone()
    data.stats.var_mean[:, :, 1] = -1.0                   # a bin in play
    with pytest.raises(DbenchInputError, match="var_mean"):
        m.denoise_device(data)
    with pytest.raises(DbenchInputError, match="reference"):
        get("statistical", backend="reference").denoise_device(upload(f, "cpu"))


def test_no_numpy_inside_a_device_call(monkeypatch):
    f = video(4, 5, 3)
    m = get("statistical", radius=1, radius_t=1, alpha=0.05)
    data = upload(f, "cpu")
    with host_conversions_refused(monkeypatch, ("numpy", "__array__", "item"), small_tolist=8):
        out = m.denoise_device(data)
    assert isinstance(out, torch.Tensor) and tuple(out.shape) == (4, 5, 3, 3)


def test_upload_carries_the_total_variance_with_the_statistics():
    f = video(3, 4, 2)
    d = upload(f, "cpu")
    assert d.kind == "transient" and tuple(d.color.shape) == (3, 4, 2, 3)
    assert d.total_var.dtype == torch.float64
    np.testing.assert_array_equal(d.total_var.numpy(), f.total_var)
    assert upload(f, "cpu", {"color"}).total_var is None


def test_stress_device_form_runs_the_transient_cases():
    from dbench.stress.cases import CASES
    from dbench.stress.device import run_device_case

    case = next(c for c in CASES if c.name == "tr_nan_voxel")
    outcome = run_device_case("statistical", case)
    assert outcome.status == "pass", outcome.why


def test_the_harness_runs_a_transient_video_on_the_device(monkeypatch):
    """The harness's device route (upload of what the method wants, the total's variance with
    the statistics; synchronised calls; download) on CPU tensors."""
    from dbench.run import harness

    monkeypatch.setattr(harness, "placement",
                        lambda m, d: (d != "cpu" and m.runs_on_device(), "cpu"))
    f = video(4, 6, 3)
    host = harness.run_cell(get("statistical", radius=1, radius_t=1), f, repeats=1)
    on_dev = harness.run_cell(get("statistical", radius=1, radius_t=1), f, repeats=1,
                              device="cuda")
    assert on_dev.backend == "triton" and host.backend == "numba"
    assert on_dev.settings["mass"] == "on"
    assert rel_err(on_dev.output, host.output) < TOL


@pytest.mark.slow
def test_bench_gpu_transient_row_dry_run():
    """``dbench bench gpu``'s transient row on CPU tensors (about 45 s through the
    interpreter: the default 11² × 3 window)."""
    from dbench.speed import gpu

    row = gpu._transient_row("cpu", 1, 1, 2, 3)
    assert "error" not in row, row.get("error")
    assert row["device_path"] and row["backend"] == "triton"
    assert row["max_rel_diff"] < TOL and row["finite_mismatch"] == 0
    assert row["hostile_nonfinite"] == row["hostile_nonfinite_host"]
    assert "| statistical (transient 2x3x2) |" in gpu.markdown(
        {"device_name": "cpu", "host": "cpu", "rows": [row]})
