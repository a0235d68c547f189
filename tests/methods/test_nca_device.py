"""nca's device path (``NCADenoiser.denoise_device``, dbench/methods/nca/device.py) on CPU
tensors: equal to the host path (ONNX Runtime) within the stated tolerance, the parameters
honoured or refused, finite output where the host's is finite, no NumPy inside the call; and
the torch kernels it shares with the autoencoder (dbench/methods/kernels/learned_torch.py)
equal to the NumPy/Numba passes they replace."""
import numpy as np
import pytest
import torch

from dbench import registry
from dbench.device import download, upload
from dbench.errors import DbenchInputError
from dbench.methods.kernels import learned_torch as lt
from dbench.methods.kernels.emitters import keep_emitters
from dbench.methods.kernels.hdr_input import autoexposure
from dbench.methods.kernels.learned_input import decode_planar, encode_planar
from dbench.methods.nca import SHIPPED_ONNX
from dbench.methods.nca.model import NCA, FoldedNCA

torch.set_num_threads(1)

#: Device output vs host output: |device − host| ≤ ATOL + RTOL |host|. Measured on the CPU over
#: 32x48 frames at 1-1024 spp and without spp, with emitters: max abs 7.7e-7, max relative
#: 7.5e-6 (|host| ≥ 0.05), from the log1p/expm1 implementations (1 ulp apart) and the
#: automaton's plain steps against the host's bias-folded unrolled graph.
ATOL, RTOL = 2e-6, 2e-5


def _frame(h=32, w=48, seed=0, spp=None, emitter=False):
    from dbench.data import Frame

    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w]
    clean = np.repeat((0.4 + 0.3 * np.sin(x / 5.0) * np.cos(y / 7.0))[..., None], 3, 2)
    normal = np.zeros((h, w, 3))
    normal[..., 2] = 1
    albedo = np.where(((x // 4 + y // 4) % 2)[..., None] == 0, 0.8, 0.3) * np.ones(3)
    color = np.maximum(clean * albedo * (1 + 0.5 * rng.standard_normal((h, w, 3))), 0)
    f = Frame(color=color, albedo=albedo, normal=normal, depth=np.full((h, w, 1), 2.0),
              meta={} if spp is None else {"spp": spp})
    if emitter:
        e = np.zeros((h, w, 1), np.float32)
        e[2:4, 3:6], e[5, 5] = 1.0, 0.25
        f = f.with_buffers(emitter=e)
    return f


def _both(method, frame):
    host = method.denoise(frame)
    out = method.denoise_device(upload(frame, "cpu"))
    assert isinstance(out, torch.Tensor) and out.dtype == torch.float32
    assert tuple(out.shape) == (*frame.shape, 3) and out.device.type == "cpu"
    return host, download(out)


@pytest.mark.parametrize("spp", [None, 1, 4, 64, 1024])
def test_device_equals_host(spp):
    m = registry.get("nca")
    assert m.device_backend == "torch" and m.has_device_path()
    for seed in range(2):
        host, dev = _both(m, _frame(seed=seed, spp=spp, emitter=seed == 1))
        np.testing.assert_allclose(dev, host, rtol=RTOL, atol=ATOL)


def test_parameters_honoured():
    f = _frame(17, 23, spp=16)
    for params in (dict(iterations=0), dict(iterations=7), dict(spp=1),
                   dict(weights=str(SHIPPED_ONNX)), dict(threads=1)):
        host, dev = _both(registry.get("nca", **params), f)
        np.testing.assert_allclose(dev, host, rtol=RTOL, atol=ATOL, err_msg=str(params))
    before = torch.get_num_threads()
    registry.get("nca", threads=2).denoise_device(upload(f, "cpu"))
    assert torch.get_num_threads() == before  # set for the call only
    with pytest.raises(DbenchInputError, match="iterations"):
        registry.get("nca", iterations=-1).denoise_device(upload(f, "cpu"))
    # a GPU has no CPU threads to set: refused before anything runs ("meta": shapes only)
    with pytest.raises(DbenchInputError, match="threads"):
        registry.get("nca", threads=2).denoise_device(upload(f, "meta"))


def test_missing_and_misshaped_buffers_name_the_buffer():
    f = _frame(8, 9)
    with pytest.raises(DbenchInputError, match="normal"):
        registry.get("nca").denoise_device(upload(f, "cpu", names=("color", "albedo")))
    bad = upload(f, "cpu")
    bad.buffers["albedo"] = bad.buffers["albedo"][:, :5]
    with pytest.raises(DbenchInputError, match="albedo"):
        registry.get("nca").denoise_device(bad)


def test_huge_and_non_finite_colour_finite_where_host_is():
    for spp in (None, 1024):
        f = _frame(spp=spp)
        color = f.color.copy()
        color[4:12, 8:20] = 3e38
        color[20, 20], color[21, 21], color[22, 22] = np.nan, np.inf, -np.inf
        g = f.with_buffers(color=color)
        with np.errstate(over="ignore"):
            host, dev = _both(registry.get("nca"), g)
        ok = np.isfinite(host)
        assert ok.mean() > 0.99 and np.isfinite(dev[ok]).all()
        # far from the block the numbers still agree (at 1 spp the block's exposure drives
        # the image to ~1e10, where float32 rounding is relatively the same)
        np.testing.assert_allclose(dev[16:], host[16:], rtol=1e-3)


def test_no_numpy_or_host_sync_inside_the_call(monkeypatch):
    m = registry.get("nca")
    f = upload(_frame(spp=4, emitter=True), "cpu")
    m.denoise_device(f)  # builds and caches the model (reads the .onnx) first
    assert list(m._device_nets) == ["cpu"]
    _forbid_host_reads(monkeypatch)
    out = m.denoise_device(f)
    monkeypatch.undo()
    assert torch.isfinite(out).all()


def _forbid_host_reads(monkeypatch):
    """Make every Python-level way of bringing a tensor's values to the host raise: NumPy
    conversion, ``.cpu()``/``.to("cpu")``, ``.item()``, ``.tolist()`` and the implicit
    ``bool``/``float``/``int`` of a tensor (each a device synchronisation on a GPU)."""
    def boom(name):
        def f(*a, **k):
            raise AssertionError(f"Tensor.{name} called inside denoise_device")
        return f

    for name in ("numpy", "cpu", "item", "tolist", "__array__", "__bool__", "__float__",
                 "__int__"):
        monkeypatch.setattr(torch.Tensor, name, boom(name))
    to = torch.Tensor.to

    def guarded_to(self, *args, **kwargs):
        for a in (*args, kwargs.get("device")):
            if isinstance(a, (str, torch.device)) and torch.device(a).type == "cpu":
                raise AssertionError("Tensor.to('cpu') called inside denoise_device")
        return to(self, *args, **kwargs)

    monkeypatch.setattr(torch.Tensor, "to", guarded_to)


def test_tf32_settings_restored():
    conv = torch.backends.cudnn.conv
    before = (conv.fp32_precision, torch.backends.cuda.matmul.fp32_precision)
    seen = []
    with lt.float32_precision():
        seen.append((conv.fp32_precision, torch.backends.cuda.matmul.fp32_precision))
    assert seen == [("ieee", "ieee")]
    assert (conv.fp32_precision, torch.backends.cuda.matmul.fp32_precision) == before


def test_folded_automaton_equals_perception_model():
    g = torch.Generator().manual_seed(0)
    for uc in ("all", "rgb"):
        nca = NCA(uc, w_init_std=0.3, generator=g, noise_gate=True, gate_init=(-3.0, 1.0),
                  gate_max=2.0)
        s = torch.rand(1, 9, 13, 17, generator=g)
        with torch.no_grad():
            nca.b.uniform_(-0.7, -0.3, generator=g)
            torch.testing.assert_close(FoldedNCA(nca)(s, 5, 0.3), nca(s, 5, 0.3),
                                       rtol=0, atol=2e-6)  # measured 6e-7


def test_torch_kernels_equal_the_host_passes():
    """learned_torch's encoding equals encode_planar (bit for bit but for log1p's last ulp),
    its decoding decode_planar, its auto-exposure autoexposure (float64, ~1e-14) and its
    keep_emitters the host's exactly, on input with every kind of bad value."""
    rng = np.random.default_rng(0)
    h, w = 37, 50
    color = (rng.random((h, w, 3)) * 2).astype(np.float32)
    color[4:12, 8:20] = 3e38
    color[20, 20], color[21, 21], color[22, 22], color[0, 0] = np.nan, np.inf, -np.inf, -3
    albedo = rng.random((h, w, 3)).astype(np.float32)
    albedo[:3, :3], albedo[5, 5], albedo[6, 6] = 1e-4, np.nan, 2.0
    normal = (rng.random((h, w, 3)) * 3 - 1.5).astype(np.float32)
    normal[7, 7] = np.inf
    depth = (rng.random((h, w, 1)) * 5).astype(np.float32)
    depth[1, 1], depth[2, 2] = np.inf, -1.0
    bufs = {"albedo": albedo, "normal": normal, "depth": depth, "level": 0.7}
    tbufs = {k: torch.from_numpy(v) if isinstance(v, np.ndarray) else v for k, v in bufs.items()}
    for col in (color, np.zeros_like(color), np.nan_to_num(color, nan=0, posinf=0).clip(0, 9)):
        ex = lt.autoexposure(torch.from_numpy(col))
        assert ex.dtype == torch.float64 and ex.ndim == 0
        assert abs(float(ex) - autoexposure(col)) <= 1e-13 * autoexposure(col)
        for feats, mult, dem in ((("normal", "albedo"), 1, True),
                                 (("normal", "albedo", "depth", "level"), 32, True),
                                 (("normal",), 1, False)):
            xh, ah = encode_planar(col, bufs, feats, float(ex), mult, dem)
            xt, at = lt.encode_planar(torch.from_numpy(col), tbufs, feats, ex, mult, dem)
            assert xt.shape == xh.shape
            np.testing.assert_allclose(xt.numpy(), xh, rtol=2e-7, atol=5e-7)  # 1 ulp: 4.8e-7
            np.testing.assert_array_equal(at.numpy(), ah)
            dh = decode_planar(xh[:3], albedo, dem, float(ex))
            dt = lt.decode_planar(torch.from_numpy(xh[:3]), at if dem else None, ex).numpy()
            np.testing.assert_allclose(dt, dh, rtol=5e-7)  # expm1's last ulp: 2.4e-7
    e = (rng.random((h, w, 1)) * 2 - 0.5).astype(np.float32)
    e[3, 3] = np.nan
    out = rng.random((h, w, 3)).astype(np.float32)
    np.testing.assert_array_equal(
        lt.keep_emitters(torch.from_numpy(color), torch.from_numpy(out),
                         torch.from_numpy(e)).numpy(), keep_emitters(color, out, e))
