"""nca (TNND, docs/methods/nca.md): filters, parameter count, identity, ONNX Runtime = PyTorch, shipped
weights, input policy, sizes."""
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
from dbench.methods.nca import SHIPPED_JSON, SHIPPED_ONNX, nca_denoise, reference_denoise
from dbench.methods.nca.export import build_onnx, weights_from_onnx
from dbench.methods.nca.model import (K_GAUSS, K_LAPLACE, K_SOBEL_X, K_SOBEL_Y, NCA,
                                      count_parameters, folded_kernel, perceive)

torch.set_num_threads(1)


def _frame(h=24, w=20, seed=0):
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w]
    clean = np.repeat((0.4 + 0.3 * np.sin(x / 5.0) * np.cos(y / 7.0))[..., None], 3, 2)
    normal = np.zeros((h, w, 3))
    normal[..., 2] = 1
    albedo = np.where(((x // 4 + y // 4) % 2)[..., None] == 0, 0.8, 0.3) * np.ones(3)
    color = clean * albedo * (1 + 0.5 * rng.standard_normal((h, w, 3)))
    return Frame(color=np.maximum(color, 0), albedo=albedo, normal=normal,
                 depth=np.ones((h, w, 1)), reference=clean * albedo)


def _random_nca(update_channels="all", seed=0, std=0.3):
    g = torch.Generator().manual_seed(seed)
    nca = NCA(update_channels, w_init_std=std, generator=g)
    with torch.no_grad():
        nca.b.uniform_(-0.7, -0.3, generator=g)
    return nca


def test_parameter_count_and_shapes():
    nca = NCA()
    assert count_parameters(nca) == 360
    assert tuple(nca.W.shape) == (39, 9) and tuple(nca.b.shape) == (9,)
    assert perceive(torch.zeros(2, 9, 5, 6)).shape == (2, 39, 5, 6)
    W, b = weights_from_onnx(__import__("onnx").load(str(SHIPPED_ONNX)))
    assert W.size + b.size == 360


@pytest.mark.parametrize("k", [1, 16, 100])
def test_identity_update(k):
    nca = NCA()  # W = 0, b = -0.5: sigmoid(0) + b = 0
    s = torch.rand(1, 9, 7, 5)
    with torch.no_grad():
        assert torch.equal(nca(s, k), s)


def test_filters():
    assert np.isclose(K_GAUSS.sum(), 1)
    for k in (K_SOBEL_X, K_SOBEL_Y, K_LAPLACE):
        assert np.isclose(k.sum(), 0)
    ramp = torch.arange(8, dtype=torch.float32).repeat(6, 1)  # s = x
    p = perceive(ramp.expand(1, 9, 6, 8).contiguous())
    sx, sy = p[0, 21:30], p[0, 30:39]
    assert torch.allclose(sx[:, :, 1:-1], torch.ones(9, 6, 6))
    assert torch.allclose(sy, torch.zeros_like(sy))
    const = perceive(torch.full((1, 9, 5, 5), 0.7))
    assert torch.allclose(const[0, 12:], torch.zeros(27, 5, 5), atol=1e-6)


def test_rgb_mode_keeps_guides_bit_for_bit():
    nca = _random_nca("rgb")
    s = torch.rand(1, 9, 9, 11)
    with torch.no_grad():
        out = nca(s, 16)
    assert torch.equal(out[:, 3:], s[:, 3:])


def test_folded_kernel_equals_perception_times_w():
    nca = _random_nca()
    s = torch.rand(2, 9, 10, 13)
    with torch.no_grad():
        z_ref = torch.einsum("nphw,pc->nchw", perceive(s), nca.W)
        K = torch.from_numpy(folded_kernel(nca.W.numpy()))
        z = torch.nn.functional.conv2d(torch.nn.functional.pad(s, (1, 1, 1, 1), "replicate"), K)
    assert torch.allclose(z, z_ref, atol=1e-5)


@pytest.mark.parametrize("update_channels", ["all", "rgb"])
@pytest.mark.parametrize("iterations", [None, 16])
def test_onnx_runtime_equals_pytorch(update_channels, iterations):
    nca = _random_nca(update_channels)
    s = torch.rand(2, 9, 17, 12)
    s[:, :3] *= 3
    with torch.no_grad():
        ref = nca(s, 16)[:, :3].numpy()
    model = build_onnx(nca.W.detach().numpy(), nca.b.detach().numpy(), update_channels,
                       iterations=iterations)
    so = ort.SessionOptions()
    so.log_severity_level = 3
    sess = ort.InferenceSession(model.SerializeToString(), so)
    feeds = {"state": s.numpy()}
    if iterations is None:
        feeds["iterations"] = np.array(16, np.int64)
        feeds["gamma"] = np.array(1.0, np.float32)
    out = sess.run(None, feeds)[0]
    assert np.abs(out - ref).max() <= 1e-4


def test_shipped_weights_onnx_equals_pytorch():
    f = _frame()
    out = nca_denoise(f.color, f.normal, f.albedo)
    ref = reference_denoise(f.color, f.normal, f.albedo)
    assert out.shape == f.color.shape and out.dtype == np.float32
    assert np.abs(out - ref).max() <= 1e-4


def test_shipped_files_load_in_a_fresh_process():
    info = json.loads(SHIPPED_JSON.read_text())
    assert info["parameters"] == 362 and "hash" in info["data"]  # 360 + the step size's 2
    assert "final_train_loss" in info["losses"]
    code = ("import numpy as np; from dbench import registry; from dbench.data import Frame; "
            "f = Frame(color=np.ones((6, 9, 3)), albedo=np.full((6, 9, 3), .5), "
            "normal=np.ones((6, 9, 3))); o = registry.get('nca').denoise(f); "
            "print(o.shape, bool(np.isfinite(o).all()))")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert res.returncode == 0, res.stderr
    assert "(6, 9, 3) True" in res.stdout


def test_denoises_a_noisy_image():
    f = _frame(48, 48)
    out = registry.get("nca").denoise(f)
    err = lambda a: np.sqrt(((a - f.reference) ** 2).mean())
    assert err(out) < err(f.color)


def test_deterministic():
    f = _frame()
    m = registry.get("nca")
    assert np.array_equal(m.denoise(f), m.denoise(f))


@pytest.mark.parametrize("shape", [(1, 1), (1, 17), (13, 7), (2, 3)])
def test_tiny_and_odd_sizes(shape):
    f = _frame(*shape)
    out = registry.get("nca").denoise(f)
    assert out.shape == (*shape, 3) and np.all(np.isfinite(out))


def test_non_finite_inputs_give_finite_output():
    f = _frame()
    color, normal, albedo = f.color.copy(), f.normal.copy(), f.albedo.copy()
    color[5, 5] = np.nan
    color[6, 6] = np.inf
    color[7, 7] = -np.inf
    normal[3, 3] = np.nan
    albedo[9, 9] = np.inf
    out = registry.get("nca").denoise(f.with_buffers(color=color, normal=normal, albedo=albedo))
    assert np.all(np.isfinite(out))
    clean = registry.get("nca").denoise(f)
    assert np.abs(out - clean)[15:, 15:].max() < 1e-3  # far from the bad pixels: unchanged


def test_iterations_parameter():
    f = _frame()
    zero = registry.get("nca", iterations=0).denoise(f)
    np.testing.assert_allclose(zero, np.maximum(f.color, 0), rtol=1e-5, atol=1e-6)
    with pytest.raises(DbenchInputError, match="iterations"):
        registry.get("nca", iterations=-1).denoise(f)


def test_bad_shapes_and_missing_buffers_name_the_buffer():
    f = _frame(8, 8)
    with pytest.raises(DbenchInputError, match="normal"):
        registry.get("nca").denoise(Frame(color=f.color, albedo=f.albedo))
    with pytest.raises(DbenchInputError, match="albedo"):
        nca_denoise(f.color, f.normal, f.albedo[:, :4])
    with pytest.raises(DbenchInputError, match="color"):
        nca_denoise(f.color[..., :2], f.normal, f.albedo)
    with pytest.raises(DbenchInputError, match="weights"):
        registry.get("nca", weights="/nonexistent/nca.onnx").denoise(f)


def test_shipped_model_converges_on_a_synthetic_image():
    """Noise falling as 1/sqrt(spp): the shipped automaton stays below the noisy input at 4,
    64 and 1024 spp and its error falls with the noise (it reads spp from the frame's meta)."""
    from learned_checks import assert_converges

    assert_converges(registry.get("nca").denoise)


def test_exposure_invariance_and_spp_from_meta():
    """Auto-exposure: scaling the input by s scales the output by s; the ``spp`` parameter
    overrides meta["spp"] and changes the step size."""
    from learned_checks import synthetic_frame

    f, _ = synthetic_frame(16)
    g, _ = synthetic_frame(16, scale=1000.0)
    a = registry.get("nca").denoise(f)
    b = registry.get("nca").denoise(g.with_buffers(color=f.color * 1000.0))
    np.testing.assert_allclose(b, a * 1000.0, rtol=1e-4, atol=1e-6)
    same = registry.get("nca", spp=16).denoise(f.with_buffers(meta={}))
    np.testing.assert_array_equal(same, a)
    assert not np.array_equal(registry.get("nca", spp=1024).denoise(f), a)


def test_directly_seen_lights_keep_the_input():
    """Pixels covered by an emitter keep the input in proportion to the coverage; without the
    buffer the output is the automaton's (the harness loads ``emitter`` as an optional need)."""
    from dbench.methods.nca import keep_emitters

    rng = np.random.default_rng(5)
    color = rng.gamma(1.0, 1.0, (6, 7, 3)).astype(np.float32)
    color[0, 0, 1] = np.nan
    out = rng.gamma(1.0, 1.0, (6, 7, 3)).astype(np.float32)
    e = np.zeros((6, 7, 1), np.float32)
    e[0, 0], e[1, 2], e[3, 3], e[4, 4] = 1.0, 1.0, 0.25, np.nan
    got = keep_emitters(color, out, e)
    np.testing.assert_array_equal(got[1, 2], color[1, 2])
    np.testing.assert_allclose(got[3, 3], out[3, 3] + 0.25 * (color[3, 3] - out[3, 3]), rtol=1e-6)
    assert got[0, 0, 1] == out[0, 0, 1] and got[0, 0, 0] == color[0, 0, 0]
    mask = np.ones((6, 7), bool)
    mask[[0, 1, 3], [0, 2, 3]] = False
    np.testing.assert_array_equal(got[mask], out[mask])
    assert keep_emitters(color, out, None) is out
    assert "emitter" in registry.get("nca").optional_needs


@pytest.mark.parametrize("encoding", ["log1p", "log1p_demodulated"])
def test_compiled_encoding_equals_the_codec(encoding):
    """The state inference builds and its decoding (kernels.learned_input) equal codec.encode
    and codec.decode within 1e-6 relative, non-finite, negative, huge and zero-albedo values
    included."""
    from dbench.methods.kernels.learned_input import decode_planar, encode_planar
    from dbench.methods.nca.codec import decode, encode

    rng = np.random.default_rng(11)
    color = rng.gamma(0.5, 2.0, (23, 31, 3)).astype(np.float32)
    color[0, 0, 0], color[1, 1, 1], color[2, 2, 2], color[3, 3, 0] = np.nan, -3, np.inf, 3e38
    albedo = rng.random((23, 31, 3)).astype(np.float32)
    albedo[5, 5], albedo[6, 6, 1] = 0.0, np.nan
    normal = rng.normal(size=(23, 31, 3)).astype(np.float32)
    normal[8, 8, 0] = -np.inf
    for exposure in (1.0, 4.5):
        ref = encode(color, normal, albedo, encoding, exposure)
        got, _ = encode_planar(color, {"albedo": albedo, "normal": normal}, ("normal", "albedo"),
                               exposure, demodulate=encoding == "log1p_demodulated")
        assert got.shape == ref.shape == (9, 23, 31)
        np.testing.assert_allclose(got, ref, rtol=1e-6, atol=1e-7)
        state = ref[:3] * 1.7
        state[0, 0, 0], state[1, 2, 3], state[2, 4, 4] = np.nan, 200.0, -np.inf
        dec = decode_planar(state, albedo, encoding == "log1p_demodulated", exposure)
        np.testing.assert_allclose(dec, decode(state, albedo, encoding, exposure), rtol=1e-6,
                                   atol=1e-7)
