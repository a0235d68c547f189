"""accumulate's device path (Accumulate.denoise_device, dbench/methods/accumulate/device.py) on CPU
tensors: the Triton kernels run in Triton's interpreter, the very source the GPU compiles
(dbench/methods/kernels/gpu/runtime.py), and must give the host's numbers frame by frame."""
import numpy as np
import pytest
import torch

from dbench import registry
from dbench.device import download, upload
from dbench.errors import DbenchInputError
from device_checks import host_conversions_refused  # pytest puts this folder on sys.path

from test_accumulate import hard_sequence

pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")  # the interpreter's NaN lanes

# Device against the host's numba backend over the 12×16 hard sequences below, measured: max abs
# difference 0 (default parameters: bit for bit, with and without a camera origin) and 1.5e-8
# (alpha_min 0.2 with TAA: the TAA's float64 blend in another order), N identical, the variance
# within 1e-7, the status maps and NaN masks identical. The tolerance sits above that.
ATOL, RTOL = 1e-6, 1e-6


def _with_camera(seq):
    """The frames with a moving camera origin in meta, so that the expected distance ‖P − o←‖
    replaces the depth in the reprojection's depth test (dbench.methods.temporal's docstring)."""
    return [f.with_buffers(meta={"camera": {"origin": [0.05 * i, -0.02 * i, 0.0]}})
            for i, f in enumerate(seq)]


def _run_both(frames, **params):
    """Yields (host output, device output as NumPy, host method, device method) per frame."""
    host = registry.get("accumulate", backend="numba", **params)
    dev = registry.get("accumulate", **params)
    host.reset()
    dev.reset()
    for f in frames:
        oh = host.denoise(f)
        od = dev.denoise_device(upload(f, "cpu"))
        assert od.dtype == torch.float32 and tuple(od.shape) == oh.shape
        yield oh, download(od), host, dev


def _assert_same(oh, od):
    fin = np.isfinite(oh)
    np.testing.assert_array_equal(np.isfinite(od), fin)  # finite exactly where the host is
    np.testing.assert_allclose(od[fin], oh[fin], rtol=RTOL, atol=ATOL)


@pytest.mark.parametrize("params,fractional,camera", [
    ({}, True, False), ({}, False, True),
    (dict(alpha_min=0.2, n_max=3, taa=True, taa_alpha=0.3), True, True)])
def test_device_equals_host_frame_by_frame(params, fractional, camera):
    seq = hard_sequence(12, 16, frames=6, fractional=fractional)
    seq = _with_camera(seq) if camera else seq
    seen = set()
    for oh, od, host, dev in _run_both(seq, **params):
        _assert_same(oh, od)
        st = dev.last["status"].numpy()
        np.testing.assert_array_equal(st, host.last["status"])
        np.testing.assert_allclose(dev.last["n"].numpy(), host.last["n"], atol=0)
        np.testing.assert_allclose(dev.last["variance"].numpy(), host.last["variance"],
                                   rtol=1e-5, atol=1e-7)
        seen |= set(np.unique(st).tolist())
    assert seen == {0, 1, 2}  # resets, bilinear and fallback taps all exercised


@pytest.mark.parametrize("taa", [False, True])
def test_hostile_inputs_finite_where_the_host_is(taa):
    seq = hard_sequence(12, 16, frames=5)
    frames = []
    for i, f in enumerate(seq):
        c = f.color.copy()
        c[2:5, 3:7] = 3e38  # clamped to ±1e15: the moments stay finite
        c[6, 1] = -np.inf
        c[7, 9] = np.nan
        frames.append(f.with_buffers(color=c, motion=None if i == 2 else f.motion))
    for (oh, od, host, dev), f in zip(_run_both(frames, taa=taa), frames):
        _assert_same(oh, od)
        assert np.isfinite(dev.last["variance"].numpy()).all()
        # finite wherever the input is, TAA included (a missing pixel's non-finite previous
        # output is no tap of TAA's history fetch, on the host and on the device)
        fin_in = np.isfinite(f.color).all(-1)
        assert np.isfinite(od[fin_in]).all() and np.isfinite(oh[fin_in]).all()
        assert (np.abs(od[2:5, 3:7]) <= 1e15).all()


def test_reset_clears_the_device_history():
    seq = hard_sequence(12, 16, frames=3, fractional=False)
    dev = registry.get("accumulate")
    dev.reset()
    for f in seq:
        dev.denoise_device(upload(f, "cpu"))
    dev.reset()
    again = download(dev.denoise_device(upload(seq[1], "cpu")))
    fresh = registry.get("accumulate")
    fresh.reset()
    first = download(fresh.denoise_device(upload(seq[1], "cpu")))
    np.testing.assert_array_equal(again, first)
    assert (dev.last["status"].numpy() == 0).all() and (dev.last["n"].numpy() <= 1).all()


def test_no_numpy_conversion_inside_a_call(monkeypatch):
    frames = [upload(f, "cpu") for f in hard_sequence(12, 16, frames=3)]
    dev = registry.get("accumulate", taa=True)
    dev.reset()

    with host_conversions_refused(monkeypatch):
        for f in frames:
            dev.denoise_device(f)
    assert dev.last["n"].numpy().max() == 3


def test_device_path_declared_and_reference_refused():
    cls = type(registry.get("accumulate"))
    assert cls.device_backend == "triton" and cls.has_device_path()
    m = registry.get("accumulate", backend="reference")
    assert not m.runs_on_device()
    with pytest.raises(DbenchInputError, match="backend"):
        m.denoise_device(upload(hard_sequence(4, 4, frames=1)[0], "cpu"))
    f = upload(hard_sequence(4, 4, frames=1)[0], "cpu")
    del f.buffers["position"]
    with pytest.raises(DbenchInputError, match="position"):
        registry.get("accumulate").denoise_device(f)
