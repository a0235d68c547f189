"""autoencoder (docs/methods/autoencoder.md): parameter count, shapes and padding, recurrence, ONNX
Runtime = PyTorch, shipped weights, input policy, sizes."""
import json
import subprocess
import sys

import numpy as np
import onnxruntime as ort
import pytest
import torch

from dbench import registry
from dbench.data import Frame
from dbench.errors import DbenchInputError
from dbench.methods.autoencoder import (SHIPPED_JSON, autoencoder_denoise, model_info,
                                        reference_denoise)
from dbench.methods.autoencoder.export import build_onnx
from dbench.methods.autoencoder.model import RecurrentAE, count_parameters, pad_to_multiple

torch.set_num_threads(1)


def _frame(h=40, w=36, seed=0):
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w]
    clean = np.repeat((0.4 + 0.3 * np.sin(x / 5.0) * np.cos(y / 7.0))[..., None], 3, 2)
    normal = np.zeros((h, w, 3))
    normal[..., 2] = 1
    albedo = np.where(((x // 4 + y // 4) % 2)[..., None] == 0, 0.8, 0.3) * np.ones(3)
    color = clean * albedo * (1 + 0.5 * rng.standard_normal((h, w, 3)))
    return Frame(color=np.maximum(color, 0), albedo=albedo, normal=normal,
                 depth=np.full((h, w, 1), 2.0), reference=clean * albedo)


def _session(model):
    so = ort.SessionOptions()
    so.log_severity_level = 3
    return ort.InferenceSession(model.SerializeToString(), so)


def test_parameter_counts():
    assert count_parameters(RecurrentAE(9)) == 1_454_924
    assert count_parameters(RecurrentAE(7)) == 1_454_348
    assert RecurrentAE(9).enc_widths == (32, 43, 57, 76, 101)


def test_shapes_and_padding():
    net = RecurrentAE(9, width_scale=0.25)
    with torch.no_grad():
        y, h = net(torch.zeros(1, 9, 128, 128))
    assert tuple(y.shape) == (1, 3, 128, 128)
    assert [tuple(t.shape[2:]) for t in h] == [(128, 128), (64, 64), (32, 32), (16, 16), (8, 8)]
    xp, hh, ww = pad_to_multiple(np.zeros((9, 100, 75), np.float32))
    assert xp.shape == (9, 128, 96) and (hh, ww) == (100, 75)
    f = _frame(100, 75)
    assert registry.get("autoencoder").denoise(f).shape == (100, 75, 3)


def test_recurrence_torch():
    torch.manual_seed(0)
    x = torch.rand(1, 9, 32, 32)
    with torch.no_grad():
        net = RecurrentAE(9, 0.25)
        y0, h = net(x)
        y1, _ = net(x, h)
        assert not torch.equal(y0, y1)  # recurrent weights are not zero
        y0b, _ = net(x)
        assert torch.equal(y0, y0b)  # reset reproduces frame 0 bit for bit
        flat = RecurrentAE(9, 0.25, recurrent=False)
        flat.load_state_dict(net.state_dict())
        z0, hz = flat(x)
        assert torch.equal(z0, flat(x, hz)[0])


@pytest.mark.parametrize("stateful,residual", [(True, False), (False, False), (True, True),
                                               (False, True)])
def test_onnx_runtime_equals_pytorch(stateful, residual):
    torch.manual_seed(1)
    net = RecurrentAE(10, 0.25, residual=residual).eval()
    state = {k: v.numpy() for k, v in net.state_dict().items()}
    sess = _session(build_onnx(state, 10, net.enc_widths, stateful=stateful, residual=residual))
    x = torch.rand(1, 10, 64, 64)
    with torch.no_grad():
        y0, h0 = net(x)
        y1, h1 = net(x * 0.5, h0)
    if stateful:
        feeds = {"x": (x * 0.5).numpy(), **{f"h{i + 1}": t.numpy() for i, t in enumerate(h0)}}
        out = sess.run(None, feeds)
        assert np.abs(out[0] - y1.numpy()).max() <= 1e-4
        for a, b in zip(out[1:], h1):
            assert np.abs(a - b.numpy()).max() <= 1e-4
    else:
        out = sess.run(None, {"x": x.numpy()})
        assert np.abs(out[0] - y0.numpy()).max() <= 1e-4
        for a, b in zip(out[1:], h0):
            assert np.abs(a - b.numpy()).max() <= 1e-4


def test_shipped_weights_onnx_equals_pytorch_over_two_frames():
    f = _frame(37, 45)
    out0, h0 = autoencoder_denoise(f.color, f.albedo, f.normal, f.depth)
    ref0, r0 = reference_denoise(f.color, f.albedo, f.normal, f.depth)
    assert np.abs(out0 - ref0).max() <= 1e-4
    out1, _ = autoencoder_denoise(f.color * 0.9, f.albedo, f.normal, f.depth, hidden=h0)
    ref1, _ = reference_denoise(f.color * 0.9, f.albedo, f.normal, f.depth, hidden=r0)
    assert np.abs(out1 - ref1).max() <= 1e-4


def test_method_state_and_reset():
    f = _frame(32, 32)
    m = registry.get("autoencoder")
    m.reset()
    a = m.denoise(f)
    m.denoise(f)
    m.reset()
    assert np.array_equal(m.denoise(f), a)
    flat = registry.get("autoencoder", recurrent=False)
    assert np.array_equal(flat.denoise(f), flat.denoise(f))
    with pytest.raises(DbenchInputError, match="reset"):
        m.denoise(_frame(64, 64))  # state of a 32x32 frame


def test_shipped_files_load_in_a_fresh_process():
    info = json.loads(SHIPPED_JSON.read_text())
    assert "hash" in info["data"] and "final_train_loss" in info["losses"]
    assert info["enc_widths"] == list(model_info()["enc_widths"])
    code = ("import numpy as np; from dbench import registry; from dbench.data import Frame; "
            "f = Frame(color=np.ones((6, 9, 3)), albedo=np.full((6, 9, 3), .5), "
            "normal=np.ones((6, 9, 3)), depth=np.ones((6, 9, 1))); "
            "o = registry.get('autoencoder').denoise(f); print(o.shape, bool(np.isfinite(o).all()))")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert res.returncode == 0, res.stderr
    assert "(6, 9, 3) True" in res.stdout


def test_denoises_a_noisy_image():
    f = _frame(64, 64)
    out = registry.get("autoencoder").denoise(f)
    err = lambda a: np.sqrt(((a - f.reference) ** 2).mean())
    assert err(out) < err(f.color)


@pytest.mark.parametrize("shape", [(1, 1), (1, 17), (13, 7), (33, 2)])
def test_tiny_and_odd_sizes(shape):
    f = _frame(*shape)
    out = registry.get("autoencoder").denoise(f)
    assert out.shape == (*shape, 3) and out.dtype == np.float32 and np.all(np.isfinite(out))


def test_non_finite_inputs_give_finite_output():
    f = _frame()
    color, normal, albedo, depth = (f.color.copy(), f.normal.copy(), f.albedo.copy(),
                                    f.depth.copy())
    color[5, 5] = np.nan
    color[6, 6] = np.inf
    color[7, 7] = -np.inf
    normal[3, 3] = np.nan
    albedo[9, 9] = np.inf
    depth[2, 2] = np.nan
    out = registry.get("autoencoder").denoise(f.with_buffers(color=color, normal=normal,
                                                            albedo=albedo, depth=depth))
    assert np.all(np.isfinite(out))


def test_bad_shapes_and_missing_buffers_name_the_buffer():
    f = _frame(8, 8)
    with pytest.raises(DbenchInputError, match="depth"):
        registry.get("autoencoder").denoise(Frame(color=f.color, albedo=f.albedo,
                                                 normal=f.normal))
    with pytest.raises(DbenchInputError, match="albedo"):
        registry.get("autoencoder").denoise(Frame(color=f.color))
    with pytest.raises(DbenchInputError, match="normal"):
        autoencoder_denoise(f.color, f.albedo, f.normal[:4], f.depth)
    with pytest.raises(DbenchInputError, match="color"):
        autoencoder_denoise(f.color[0], f.albedo, f.normal, f.depth)


def test_shipped_model_converges_on_a_synthetic_image():
    """Noise falling as 1/sqrt(spp): the shipped autoencoder stays below the noisy input at 4,
    64, 256 and 1024 spp and its error falls with the noise (it reads spp from the frame's
    meta). Before the consistency stage it was worse than its input at 1024 spp here."""
    from learned_checks import assert_converges

    assert_converges(registry.get("autoencoder").denoise, spps=(4, 64, 256, 1024))


def test_directly_seen_lights_keep_the_input():
    """keep_emitters (the NCA's rule): covered pixels keep the input in proportion to their
    coverage; the rest is the network's output."""
    from learned_checks import synthetic_frame

    f, _ = synthetic_frame(16)
    h, w = f.color.shape[:2]
    e = np.zeros((h, w, 1), np.float32)
    e[2:4, 3:6] = 1.0
    e[5, 5] = 0.25
    plain = registry.get("autoencoder").denoise(f)
    lit = registry.get("autoencoder").denoise(f.with_buffers(emitter=e))
    np.testing.assert_array_equal(lit[2:4, 3:6], f.color[2:4, 3:6].astype(np.float32))
    np.testing.assert_allclose(lit[5, 5], plain[5, 5] + 0.25 * (f.color[5, 5] - plain[5, 5]),
                               rtol=1e-5)
    mask = e[..., 0] == 0
    np.testing.assert_array_equal(lit[mask], plain[mask])


def test_exposure_invariance_and_spp_from_meta():
    from learned_checks import synthetic_frame

    f, _ = synthetic_frame(16)
    a = registry.get("autoencoder").denoise(f)
    b = registry.get("autoencoder").denoise(f.with_buffers(color=f.color * 1000.0))
    np.testing.assert_allclose(b, a * 1000.0, rtol=1e-3, atol=1e-5)
    same = registry.get("autoencoder", spp=16).denoise(f.with_buffers(meta={}))
    np.testing.assert_allclose(same, a, rtol=1e-6)
    assert not np.array_equal(registry.get("autoencoder", spp=1024).denoise(f), a)


@pytest.mark.parametrize("h,w,exposure", [(37, 45, 1.0), (64, 32, 3.7), (33, 70, 0.01)])
def test_compiled_encoding_equals_encode_then_pad(h, w, exposure):
    """kernels.learned_input.encode_planar (what inference runs) equals codec.encode then
    pad_to_multiple within 1e-6 relative, non-finite, negative, huge and zero-albedo values
    included; the same a_eff."""
    from dbench.methods.autoencoder.codec import encode, pad_to_multiple
    from dbench.methods.autoencoder.codec import MULTIPLE
    from dbench.methods.kernels.learned_input import encode_planar

    rng = np.random.default_rng(h * w)
    color = rng.gamma(0.5, 2.0, (h, w, 3)).astype(np.float32)
    color[0, 0, 0], color[1, 1, 1], color[2, 2, 2], color[3, 3, 0] = np.nan, -3, np.inf, 3e38
    albedo = rng.random((h, w, 3)).astype(np.float32)
    albedo[5, 5], albedo[6, 6, 1], albedo[7, 7, 2] = 0.0, np.nan, 1.5
    normal = rng.normal(size=(h, w, 3)).astype(np.float32)
    normal[8, 8, 0] = np.inf
    depth = (rng.random((h, w, 1)) * 5).astype(np.float32)
    depth[9, 9], depth[10, 10] = np.nan, -1.0
    bufs = {"albedo": albedo, "normal": normal, "depth": depth, "level": 0.3}
    for feats in (("normal", "albedo", "depth", "level"), ("normal", "albedo", "depth")):
        x, a_eff = encode(color, bufs, feats, exposure)
        ref, _, _ = pad_to_multiple(x)
        got, a_fast = encode_planar(color, bufs, feats, exposure, MULTIPLE)
        assert got.shape == ref.shape and got.dtype == np.float32
        np.testing.assert_allclose(got, ref, rtol=1e-6, atol=1e-7)
        np.testing.assert_array_equal(a_fast, a_eff)
