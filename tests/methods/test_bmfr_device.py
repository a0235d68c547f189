"""bmfr's device path (BMFR.denoise_device, dbench/methods/bmfr/device.py) on CPU tensors:
Triton's interpreter runs the kernels the GPU compiles (dbench/methods/kernels/gpu/runtime.py),
and every frame must equal the host's numba backend.

Tolerance, measured on these sequences (12×16, 8×8 blocks: 3×3 blocks with the cycling grid
offsets, rank-deficient blocks whose safeguard drops columns): output max abs difference 1.9e-7
and max |Δ| / (|host| + 1e-3) 2.4e-6 (the float64 sums of the Householder QR and of the
reconstruction run in another order than the host's; the hand-back's float32 window sums in the
same order); N1/N2 identical (1.2e-7 with the temporal gradient: N' in float64 vs float32),
reprojection status and non-finite masks identical, the dropped column counts equal."""
import numpy as np
import pytest
import torch

from dbench import registry
from dbench.device import download, upload
from dbench.errors import DbenchInputError
from device_checks import host_conversions_refused  # pytest puts this folder on sys.path

from test_accumulate import hard_sequence
from test_svgf_device import rich_sequence

pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")  # the interpreter's NaN lanes

RTOL, ATOL = 1e-5, 1e-6
BLOCK = 8  # 12×16 frames: 2×2 … 3×3 blocks


def run_both(frames, **params):
    """Yields (host output, device output as NumPy, host method, device method) per frame."""
    params.setdefault("block_size", BLOCK)
    host = registry.get("bmfr", backend="numba", **params)
    dev = registry.get("bmfr", **params)
    assert dev.runs_on_device() and dev.device_backend == "triton"
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
    for key in ("n1", "n2"):
        np.testing.assert_allclose(dev.last[key].numpy(), host.last[key], rtol=1e-6, atol=1e-6)
    assert int(dev.last["dropped"]) == host.last["dropped"]
    assert dev.last["offset"] == host.last["offset"]


def test_defaults_equal_host_with_emission_gradient_and_layout_change():
    """Default parameters (paper features, signed hand-back, temporal gradient) on frames with
    emission (absent on the fourth: the history restarts), a gradient buffer, NaN/Inf colour,
    NaN motion and disocclusions."""
    grads = 0
    for oh, od, host, dev in run_both(rich_sequence(5)):
        assert_same(oh, od, host, dev)
        if host.last["gradient"] is not None:
            grads += 1
            np.testing.assert_allclose(dev.last["gradient"].numpy(), host.last["gradient"],
                                       atol=1e-6)
    assert grads == 5


@pytest.mark.parametrize("params", [
    dict(handback="wiener", taa=True, features="seed", temporal_gradient=False, seed=5000),
    pytest.param(dict(preset="paper", features="positions", clamp_negative=False,
                      noise_amount=0.0, block_size=5, alpha1=0.5), marks=pytest.mark.slow),
])
def test_settings_equal_host(params):
    for oh, od, host, dev in run_both(hard_sequence(12, 16, frames=4, fractional=True),
                                      **params):
        assert_same(oh, od, host, dev)


def test_hostile_frames_finite_where_host_is():
    """A 3e38 block, NaN/Inf colour, a frame without motion (history reset), disocclusions.
    The frame with the block (clamped to 1e15) is compared against its largest value: a block
    fitted to 1e15 leaves float64 cancellation of ~1e15 · 2⁻⁵² in every pixel it reconstructs,
    so the host's and the device's summation orders differ there by up to 5.2e-10 of 1e15
    (measured; 0.07 against 0.12 at a pixel beside it). Every other frame as tightly as above."""
    frames = hard_sequence(12, 16, frames=4)
    col = frames[1].color.copy()
    col[2:6, 3:9] = 3e38
    col[7, 2] = -3e38
    frames[1] = frames[1].with_buffers(color=col)
    frames[2] = frames[2].with_buffers(motion=None)
    for i, (oh, od, host, dev) in enumerate(run_both(frames)):
        fin = np.isfinite(oh)
        assert fin.any()
        if i == 1:
            np.testing.assert_array_equal(np.isfinite(od), fin)
            assert np.abs(od[fin] - oh[fin]).max() <= 1e-8 * np.abs(oh[fin]).max()
            assert int(dev.last["dropped"]) == host.last["dropped"]
        else:
            assert_same(oh, od, host, dev)
    assert dev.last["status"].numpy().any()  # the frame after the missing motion reprojects


def test_reset_clears_device_history():
    frames = hard_sequence(12, 16, frames=2)
    m = registry.get("bmfr", block_size=BLOCK)
    m.reset()
    first = download(m.denoise_device(upload(frames[0], "cpu")))
    m.denoise_device(upload(frames[1], "cpu"))
    m.reset()
    assert m.frame_index == 0 and not m._device_history.has_prev
    again = download(m.denoise_device(upload(frames[0], "cpu")))
    np.testing.assert_array_equal(again, first)
    assert not m.last["status"].numpy().any()


def test_no_numpy_inside_a_call(monkeypatch):
    frames = rich_sequence(2)
    m = registry.get("bmfr", block_size=BLOCK, taa=True)
    m.reset()
    ups = [upload(f, "cpu") for f in frames]

    with host_conversions_refused(monkeypatch):
        outs = [m.denoise_device(u) for u in ups]
    assert all(isinstance(o, torch.Tensor) and o.shape == (12, 16, 3) for o in outs)


@pytest.mark.parametrize("params, name", [
    (dict(samples=36), "samples"), (dict(preset="seed"), "samples"),
    (dict(features="reflected"), "features"), (dict(block_size=128), "block_size"),
    (dict(backend="reference"), "backend"),
])
def test_unported_settings_stay_on_host(params, name):
    m = registry.get("bmfr", **params)
    assert not m.runs_on_device()
    frame = hard_sequence(12, 16, frames=1)[0]
    with pytest.raises(DbenchInputError, match=name):
        m.denoise_device(upload(frame, "cpu"))
