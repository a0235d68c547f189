"""``oidn`` on a device (``denoise_device``): OIDN's CPU device on CPU tensors here, OIDN's
CUDA device on CUDA tensors where a GPU is usable.

Tolerance: on CPU tensors the device path runs the same OIDN CPU device type, the same RT filter
settings and the same input policy as the host path, so the outputs are compared bit for bit
(measured: max |difference| 0.0 for every feature set and quality). On CUDA the network runs
in half precision on tensor cores, so it is compared to the host result within the tolerance
stated at that test.
"""
from __future__ import annotations

import pickle

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("pyoidn")

from dbench import registry  # noqa: E402
from dbench.data import Frame  # noqa: E402
from dbench.device import cuda_usable, upload  # noqa: E402
from dbench.errors import DbenchInputError  # noqa: E402


def _frame(h=32, w=48, seed=0, noise=0.2):
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w]
    clean = np.repeat((0.3 + 0.2 * np.sin(x / 6.0) * np.cos(y / 9.0))[..., None], 3, 2)
    color = (clean + noise * rng.standard_normal(clean.shape)).astype(np.float32)
    albedo = np.full((h, w, 3), 0.7, np.float32)
    albedo[:, : w // 2] = 0.3
    normal = np.zeros((h, w, 3), np.float32)
    normal[..., 2] = 1
    return Frame(color=color, albedo=albedo, normal=normal, reference=clean)


def test_registered_device_backend():
    m = registry.get("oidn")
    assert m.has_device_path() and m.device_backend == "oidn-cuda"


@pytest.mark.parametrize("features", ["albedo+normal", "albedo", "none"])
@pytest.mark.parametrize("quality", ["high", "balanced", "fast"])
def test_cpu_tensors_equal_host_path(features, quality):
    f = _frame()
    m = registry.get("oidn", features=features, quality=quality)
    out = m.denoise_device(upload(f, "cpu"))
    assert isinstance(out, torch.Tensor) and out.dtype == torch.float32
    assert tuple(out.shape) == f.color.shape and out.device.type == "cpu"
    assert m.last_settings["oidn_device"] == "cpu" and m.last_settings["quality"] == quality
    assert m.last_settings["features"] == features
    host = m.denoise(f)
    np.testing.assert_array_equal(out.numpy(), host)


def test_quality_features_and_clean_aux_change_the_result():
    d = upload(_frame(), "cpu")
    outs = {key: registry.get("oidn", **dict(key)).denoise_device(d).numpy()
            for key in [(), (("quality", "fast"),), (("features", "none"),),
                        (("clean_aux", False),)]}
    base = outs[()]
    for key, out in outs.items():
        if key:
            assert np.abs(out - base).max() > 1e-4, key


def test_reduces_error_and_leaves_inputs_alone():
    f = _frame()
    d = upload(f, "cpu")
    before = {k: v.clone() for k, v in d.buffers.items()}
    out = registry.get("oidn").denoise_device(d).numpy()
    err = lambda a: np.sqrt(((a - f.reference) ** 2).mean())  # noqa: E731
    assert err(out) < 0.5 * err(f.color)
    for k, v in d.buffers.items():
        assert torch.equal(v, before[k]), k


def test_huge_and_non_finite_inputs_give_finite_output_like_the_host():
    f = _frame()
    color = f.color.copy()
    color[4:10, 4:10] = 3e38
    color[20, 20] = np.nan
    color[21, 21, 1] = np.inf
    color[22, 22] = -5
    albedo = f.albedo.copy()
    albedo[3, 3] = np.nan
    albedo[3, 4] = np.inf
    normal = f.normal.copy()
    normal[5, 5] = np.nan
    normal[5, 6] = -np.inf
    g = f.with_buffers(color=color, albedo=albedo, normal=normal)
    m = registry.get("oidn")
    out = m.denoise_device(upload(g, "cpu")).numpy()
    assert np.isfinite(out).all()
    np.testing.assert_array_equal(out, m.denoise(g))
    # NaN pixels alone do not poison their neighbourhood
    h = f.with_buffers(color=np.where(np.isnan(color), np.nan, f.color).astype(np.float32))
    out = m.denoise_device(upload(h, "cpu")).numpy()
    assert np.isfinite(out).all() and np.abs(out[17:24, 17:24] - f.reference[17:24, 17:24]).max() < 1.0


def test_filter_kept_across_calls_and_rebuilt_on_size_change():
    m = registry.get("oidn")
    d = upload(_frame(), "cpu")
    a = m.denoise_device(d)
    runner = m._runner
    flt = runner.filter
    b = m.denoise_device(upload(_frame(seed=1), "cpu"))
    assert m._runner is runner and runner.filter is flt
    assert runner.filter_builds == 1 and runner.device_builds == 1
    assert a.data_ptr() != b.data_ptr()  # a later call never overwrites an earlier result
    assert not torch.equal(a, b)
    np.testing.assert_array_equal(a.numpy(), m.denoise_device(d).numpy())
    c = m.denoise_device(upload(_frame(16, 24), "cpu"))
    assert tuple(c.shape) == (16, 24, 3)
    assert runner.filter_builds == 2 and runner.device_builds == 1
    m.params["quality"] = "fast"  # the key holds the quality too
    m.denoise_device(upload(_frame(16, 24), "cpu"))
    assert runner.filter_builds == 3 and runner.device_builds == 1
    runner.close()
    m.denoise_device(d)
    assert runner.device_builds == 2


def test_odd_sizes_missing_buffers_and_pickling():
    m = registry.get("oidn")
    for shape in [(1, 1), (13, 7)]:
        out = m.denoise_device(upload(_frame(*shape), "cpu"))
        assert tuple(out.shape) == (*shape, 3) and torch.isfinite(out).all()
    f = _frame()
    with pytest.raises(DbenchInputError, match="normal"):
        m.denoise_device(upload(f.with_buffers(normal=None), "cpu"))
    with pytest.raises(DbenchInputError, match="albedo"):
        registry.get("oidn", features="albedo").denoise_device(
            upload(f.with_buffers(albedo=None), "cpu"))
    out = registry.get("oidn", features="none").denoise_device(
        upload(f.with_buffers(albedo=None, normal=None), "cpu"))
    assert torch.isfinite(out).all()
    clone = pickle.loads(pickle.dumps(m))
    assert clone._runner is None and clone.params == m.params


@pytest.mark.skipif(not cuda_usable(), reason="no usable CUDA GPU")
def test_cuda_tensors_on_oidn_cuda_device():
    # OIDN's CUDA device runs the network in half precision: measured on an H200 against the
    # host (CPU device) result on this 64x96 frame (values about 0.1-0.6), max |diff| 2.3e-3
    # (high, albedo+normal), at most 6.9e-3 over every quality and feature set; 1e-2 allowed
    f = _frame(64, 96)
    m = registry.get("oidn")
    d = upload(f, "cuda")
    out = m.denoise_device(d)
    torch.cuda.synchronize()
    assert out.device.type == "cuda" and out.dtype == torch.float32
    assert m.last_settings["oidn_device"] == "cuda"
    host = m.denoise(f)
    np.testing.assert_allclose(out.cpu().numpy(), host, atol=1e-2, rtol=0)
    flt = m._runner.filter
    again = m.denoise_device(d)
    assert m._runner.filter is flt and m._runner.filter_builds == 1
    assert torch.equal(again, out) and again.data_ptr() != out.data_ptr()
    side = torch.cuda.Stream()
    with torch.cuda.stream(side):  # a new current stream: a new OIDN device bound to it
        on_side = m.denoise_device(d)
    side.synchronize()
    assert m._runner.device_builds == 2 and torch.equal(on_side, out)
