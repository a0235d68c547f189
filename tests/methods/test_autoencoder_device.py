"""autoencoder's device path (``Autoencoder.denoise_device``,
dbench/methods/autoencoder/device.py) on CPU tensors: equal to the host path (ONNX Runtime)
within the stated tolerance frame by frame over a recurrent sequence and after ``reset()``, the
hidden states kept as tensors on the device, the parameters honoured or refused, finite output
where the host's is finite, no NumPy inside the call."""
import numpy as np
import pytest
import torch

from dbench import registry
from dbench.device import download, upload
from dbench.errors import DbenchInputError
from dbench.methods.autoencoder import SHIPPED_ONNX

torch.set_num_threads(1)

#: Device output vs host output: |device − host| ≤ ATOL + RTOL |host|. Measured on the CPU over
#: recurrent and stateless sequences of 32x48 frames at 1-1024 spp with emitters: max abs
#: 1.4e-6, max relative 1.2e-5 (|host| ≥ 0.05), from float32 summation order in the
#: convolutions (PyTorch's against ONNX Runtime's, and the zero hidden state of frame 0 against
#: the host's stateless graph) and log1p/expm1's last ulp.
ATOL, RTOL = 3e-6, 3e-5


def _frame(h=32, w=48, seed=0, spp=None, emitter=False, shift=0):
    from dbench.data import Frame

    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w]
    x = x + shift  # a camera pan across a sequence
    clean = np.repeat((0.4 + 0.3 * np.sin(x / 5.0) * np.cos(y / 7.0))[..., None], 3, 2)
    normal = np.zeros((h, w, 3))
    normal[..., 2] = 1
    albedo = np.where(((x // 4 + y // 4) % 2)[..., None] == 0, 0.8, 0.3) * np.ones(3)
    color = np.maximum(clean * albedo * (1 + 0.5 * rng.standard_normal((h, w, 3))), 0)
    f = Frame(color=color, albedo=albedo, normal=normal, depth=2.0 + (y / h)[..., None],
              meta={} if spp is None else {"spp": spp})
    if emitter:
        e = np.zeros((h, w, 1), np.float32)
        e[2:4, 3:6], e[5, 5] = 1.0, 0.25
        f = f.with_buffers(emitter=e)
    return f


def _sequence(n=4, spp=4, **kw):
    return [_frame(seed=t, spp=spp, shift=t, emitter=t == 1, **kw) for t in range(n)]


def _run(method, frames, device=True):
    if device:
        return [download(method.denoise_device(upload(f, "cpu"))) for f in frames]
    return [method.denoise(f) for f in frames]


@pytest.mark.parametrize("spp", [None, 1, 1024])
def test_sequence_equals_host_and_reset(spp):
    host_m, dev_m = registry.get("autoencoder"), registry.get("autoencoder")
    assert dev_m.device_backend == "torch" and dev_m.has_device_path()
    frames = _sequence(spp=spp)
    host, dev = _run(host_m, frames, False), _run(dev_m, frames)
    for t, (h, d) in enumerate(zip(host, dev)):
        np.testing.assert_allclose(d, h, rtol=RTOL, atol=ATOL, err_msg=f"frame {t}")
    # the state lives on the device, one tensor per level
    assert all(isinstance(s, torch.Tensor) and s.device.type == "cpu" for s in dev_m._hidden)
    assert [tuple(s.shape[2:]) for s in dev_m._hidden] == [(32, 64), (16, 32), (8, 16),
                                                           (4, 8), (2, 4)]
    assert np.abs(dev[2] - _run(registry.get("autoencoder"), frames[2:3])[0]).max() > 1e-6
    dev_m.reset()
    assert dev_m._hidden is None
    again = _run(dev_m, frames[:2])
    np.testing.assert_array_equal(again[0], dev[0])  # reset: frame 0 once more, bit for bit
    np.testing.assert_array_equal(again[1], dev[1])


def test_state_passes_between_host_and_device_paths():
    frames = _sequence(3)
    host = _run(registry.get("autoencoder"), frames, False)
    m = registry.get("autoencoder")
    a = m.denoise(frames[0])
    b = download(m.denoise_device(upload(frames[1], "cpu")))
    c = m.denoise(frames[2])
    for got, want in zip((a, b, c), host):
        np.testing.assert_allclose(got, want, rtol=RTOL, atol=ATOL)


def test_parameters_honoured():
    frames = _sequence(2, spp=16)
    for params in (dict(recurrent=False), dict(spp=1), dict(weights=str(SHIPPED_ONNX)),
                   dict(threads=1)):
        host = _run(registry.get("autoencoder", **params), frames, False)
        dev = _run(registry.get("autoencoder", **params), frames)
        for h, d in zip(host, dev):
            np.testing.assert_allclose(d, h, rtol=RTOL, atol=ATOL, err_msg=str(params))
    flat = registry.get("autoencoder", recurrent=False)
    _run(flat, frames)
    assert flat._hidden is None
    before = torch.get_num_threads()
    _run(registry.get("autoencoder", threads=2), frames[:1])
    assert torch.get_num_threads() == before  # set for the call only
    # a GPU has no CPU threads to set: refused before anything runs ("meta": shapes only)
    with pytest.raises(DbenchInputError, match="threads"):
        registry.get("autoencoder", threads=2).denoise_device(upload(frames[0], "meta"))


def test_bad_input_names_the_buffer_or_the_state():
    f = _frame(8, 9)
    m = registry.get("autoencoder")
    for missing in ("albedo", "depth", "normal"):
        names = {"color", "albedo", "normal", "depth"} - {missing}
        with pytest.raises(DbenchInputError, match=missing):
            m.denoise_device(upload(f, "cpu", names=names))
    m.denoise_device(upload(f, "cpu"))
    with pytest.raises(DbenchInputError, match="reset"):
        m.denoise_device(upload(_frame(40, 40), "cpu"))  # state of a 32x32 padded frame


def test_huge_and_non_finite_colour_finite_where_host_is():
    for spp in (None, 1024):
        f = _frame(spp=spp)
        color = f.color.copy()
        color[4:12, 8:20] = 3e38
        color[20, 20], color[21, 21], color[22, 22] = np.nan, np.inf, -np.inf
        g = f.with_buffers(color=color)
        with np.errstate(over="ignore"):
            host = registry.get("autoencoder").denoise(g)
        dev = download(registry.get("autoencoder").denoise_device(upload(g, "cpu")))
        ok = np.isfinite(host)
        # the host path overflows where expm1(80) · a_eff is divided by the tiny exposure the
        # block causes (measured: 0.35-0.69 % of the values); the device path matches it
        assert ok.mean() > 0.99 and np.isfinite(dev[ok]).all()


def test_no_numpy_or_host_sync_inside_the_call(monkeypatch):
    from test_nca_device import _forbid_host_reads

    m = registry.get("autoencoder")
    frames = [upload(f, "cpu") for f in _sequence(2)]
    m.denoise_device(frames[0])  # builds and caches the model (reads the .onnx) first
    assert list(m._device_nets) == ["cpu"]
    _forbid_host_reads(monkeypatch)
    out = m.denoise_device(frames[1])  # with the recurrent state
    monkeypatch.undo()
    assert torch.isfinite(out).all()
