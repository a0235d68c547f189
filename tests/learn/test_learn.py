"""dbench.learn: losses, training scenes, training sets, reproducible training, shipping, CLI."""
import numpy as np
import pytest
import torch

from dbench.learn import losses as L
from dbench.learn import train as T
from dbench.learn.dataset import TrainingSet, sample_batch, synthetic_training_set
from dbench.learn.scenes import EVALUATION_SCENES, procedural_texture, training_scene

torch.set_num_threads(1)


# ---------------------------------------------------------------------------------------------
# losses (docs/methods/autoencoder.md §6.4)


def test_losses_vanish_for_equal_images():
    p = torch.rand(2, 3, 16, 12)
    for fn in (L.l1, L.mse, L.gradient_loss, L.hfen, L.clamped_linear_mse):
        assert float(fn(p, p)) == 0.0
    seq = torch.rand(2, 4, 3, 8, 8)
    assert float(L.temporal_loss(seq, seq)) == 0.0
    static = torch.rand(2, 1, 3, 8, 8).expand(2, 5, 3, 8, 8)
    assert float(L.temporal_loss(static + 0.3, static)) == 0.0  # P = T + constant, static
    total, parts = L.autoencoder_loss(seq, seq)
    assert float(total) == 0.0 and set(parts) == {"l1", "hfen", "temporal"}


def test_loss_values_and_weights():
    p, t = torch.zeros(1, 3, 8, 8), torch.full((1, 3, 8, 8), 0.5)
    assert np.isclose(float(L.l1(p, t)), 0.5) and np.isclose(float(L.mse(p, t)), 0.25)
    assert float(L.gradient_loss(p, t)) == pytest.approx(0.0, abs=1e-7)  # constants: no edges
    assert len(L.FRAME_WEIGHTS) == 7 and L.FRAME_WEIGHTS[-1] == 1.0
    assert abs(L.log_kernel().sum()) < 1e-6
    step = torch.zeros(1, 1, 8, 8)
    step[..., 4:] = 1
    assert float(L.gradient_loss(step, torch.zeros_like(step))) > 0
    assert L.AE_WEIGHTS == {"l1": 0.8, "hfen": 0.1, "temporal": 0.1}


# ---------------------------------------------------------------------------------------------
# training scenes and sets


def test_training_scenes_are_not_evaluation_scenes(renderer):
    from dbench.datasets.scenes import catalogue as scenes

    names = [training_scene(i).name for i in range(6)]
    assert not set(names) & set(scenes.available())
    assert set(EVALUATION_SCENES) <= set(scenes.available())
    from dbench.datasets.cache import canonical

    a = canonical(training_scene(3).scene_dict(renderer, 8))
    b = canonical(training_scene(3).scene_dict(renderer, 8))
    c = canonical(training_scene(4).scene_dict(renderer, 8))
    assert a == b and a != c  # deterministic per index, different across indices
    img = np.array(renderer.render(renderer.load_dict(training_scene(0).scene_dict(renderer, 8)),
                                   spp=1))
    assert img.shape == (8, 8, 3) and np.isfinite(img).all()


def test_procedural_textures():
    a = procedural_texture(5, 32)
    assert a.shape == (32, 32, 3) and a.min() >= 0.02 and a.max() <= 0.95
    assert np.array_equal(a, procedural_texture(5, 32))


def test_sample_batch_shapes_and_determinism():
    ts = synthetic_training_set(3, 32, (1, 4))
    b1 = sample_batch(ts, np.random.default_rng(0), 5, 16)
    b2 = sample_batch(ts, np.random.default_rng(0), 5, 16)
    assert b1["noisy"].shape == (5, 16, 16, 3) and b1["depth"].shape == (5, 16, 16, 1)
    for k in b1:
        assert np.array_equal(b1[k], b2[k])
    assert set(b1["spp"]) <= {1, 4}
    only4 = sample_batch(ts, np.random.default_rng(1), 6, 16, spp_choices=(4,))
    assert set(only4["spp"]) == {4}


def test_training_set_hash_and_checks():
    ts = synthetic_training_set(2, 16, (1,))
    h = ts.hash
    assert h == synthetic_training_set(2, 16, (1,)).hash
    assert h != synthetic_training_set(2, 16, (1,), seed=1).hash
    from dbench.errors import DbenchInputError
    with pytest.raises(DbenchInputError, match="reference"):
        TrainingSet(noisy=ts.noisy, spp=ts.spp, reference=ts.reference[:, :8], albedo=ts.albedo,
                    normal=ts.normal, depth=ts.depth, scenes=ts.scenes)


# ---------------------------------------------------------------------------------------------
# training


def _nca_cfg(**kw):
    return T.NCAConfig(**{"steps": 6, "batch": 2, "crop": 16, "k_min": 2, "k_max": 5,
                          "iterations": 3, **kw})


def _ae_cfg(**kw):
    return T.AEConfig(**{"steps": 4, "batch": 2, "crop": 32, "width_scale": 0.25, **kw})


def test_nca_training_is_reproducible():
    ts = synthetic_training_set(3, 32, (1, 4))
    a = T.train_nca(ts, _nca_cfg(seed=3))
    b = T.train_nca(ts, _nca_cfg(seed=3))
    c = T.train_nca(ts, _nca_cfg(seed=4))
    assert a.losses == b.losses and len(a.losses) == 6
    assert torch.equal(a.model.W, b.model.W)
    assert a.losses != c.losses


def test_autoencoder_training_is_reproducible():
    ts = synthetic_training_set(3, 32, (1, 4))
    a = T.train_autoencoder(ts, _ae_cfg(seed=5))
    b = T.train_autoencoder(ts, _ae_cfg(seed=5))
    assert a.losses == b.losses and len(a.losses) == 4


def test_autoencoder_training_reduces_the_loss():
    """docs/methods/autoencoder.md §6.5: 20 steps on a synthetic set reduce the loss by >= 20 %."""
    ts = synthetic_training_set(4, 32, (1,))
    r = T.train_autoencoder(ts, _ae_cfg(steps=20, batch=4, lr=3e-3, lr_decay_at=(),
                                        residual=False))
    assert np.mean(r.losses[-4:]) <= 0.8 * np.mean(r.losses[:4])


def test_ship_and_load_trained_weights(tmp_path):
    from dbench import registry
    from dbench.data import Frame

    ts = synthetic_training_set(3, 32, (1, 4))
    tr, va = T.split(ts, 1)
    nca = T.train_nca(tr, _nca_cfg(color_encoding="log1p_demodulated", linear_weight=0.1),
                      validation=va)
    assert "linear" in nca.parts[-1]
    onnx_path, json_path = T.ship_nca(nca, tmp_path)
    info = __import__("json").loads(json_path.read_text())
    # the seed's 360 numbers plus the two of the noise gate's step size
    assert info["parameters"] == 362 and info["data"]["hash"] == tr.hash
    assert info["autoexposure"] is True and len(info["noise_gate"]) == 3  # u, v, γ_max
    assert info["color_encoding"] == "log1p_demodulated"
    assert info["losses"]["steps_done"] == 6 and "loss" in info["losses"]["validation"]
    # the level-gated variant (an option, off by default) ships and loads like the plain one
    ae = T.train_autoencoder(tr, _ae_cfg(level_gate=True), validation=va)
    ae_onnx, ae_json = T.ship_autoencoder(ae, tmp_path)
    gate = __import__("json").loads(ae_json.read_text())["level_gate"]
    assert gate["channel"] == 10 and set(gate["gamma_at_spp"]) == {"1", "4", "16", "64", "256",
                                                                    "1024"}
    f = Frame(color=ts.noisy[0, 0, :20, :13], albedo=ts.albedo[0, :20, :13],
              normal=ts.normal[0, :20, :13], depth=ts.depth[0, :20, :13])
    assert registry.get("nca", weights=str(onnx_path)).denoise(f).shape == (20, 13, 3)
    assert registry.get("autoencoder", weights=str(ae_onnx)).denoise(f).shape == (20, 13, 3)
    from dbench.methods.nca import nca_denoise, reference_denoise

    for spp in (None, 1, 37, 1024):  # the step size follows the sample count
        a = nca_denoise(f.color, f.normal, f.albedo, weights=onnx_path, spp=spp)
        b = reference_denoise(f.color, f.normal, f.albedo, weights=onnx_path, spp=spp)
        assert np.abs(a - b).max() <= 1e-4
    from dbench.methods.autoencoder import autoencoder_denoise
    from dbench.methods.autoencoder import reference_denoise as ae_reference

    for spp in (1, 256):
        a = autoencoder_denoise(f.color, f.albedo, f.normal, f.depth, weights=ae_onnx, spp=spp)[0]
        b = ae_reference(f.color, f.albedo, f.normal, f.depth, weights=ae_onnx, spp=spp)[0]
        assert np.abs(a - b).max() <= 1e-4


def test_loop_form_equals_unrolled_with_step_size():
    """The shipped Loop form (γ an input) and the unrolled form (γ built in) agree."""
    import onnxruntime as ort

    from dbench.methods.nca.export import build_onnx

    rng = np.random.default_rng(3)
    W = rng.normal(0, 0.3, (39, 9)).astype(np.float32)
    b = rng.normal(-0.5, 0.1, 9).astype(np.float32)
    state = rng.random((1, 9, 11, 13)).astype(np.float32)
    loop = ort.InferenceSession(build_onnx(W, b).SerializeToString())
    for gamma in (1.0, 0.3):
        unrolled = ort.InferenceSession(build_onnx(W, b, iterations=3, gamma=gamma)
                                        .SerializeToString())
        a = loop.run(None, {"state": state, "iterations": np.array(3, np.int64),
                            "gamma": np.array(gamma, np.float32)})[0]
        c = unrolled.run(None, {"state": state})[0]
        assert np.abs(a - c).max() <= 1e-5


def test_mixed_spp_inputs_and_exposure():
    """Sums of independent renders give exact inputs at the summed count; the exposed batch
    scales noisy and reference alike."""
    from dbench.learn.dataset import combine_spp, mixed_spp, sample_batch

    rng = np.random.default_rng(0)
    spp = (1, 2, 4, 8)
    drawn = [sum(spp[i] for i in mixed_spp(spp, [0, 1, 2, 3], rng)) for _ in range(400)]
    assert set(drawn) == set(range(1, 16))  # every count from 1 to 15 occurs
    x = [np.full((2, 2, 3), v, np.float32) for v in (1.0, 2.0, 4.0, 8.0)]
    assert np.allclose(combine_spp(x, spp, [1, 3]), (2 * 2 + 8 * 8) / 10)
    ts = synthetic_training_set(3, 32, spp)
    b = sample_batch(ts, np.random.default_rng(1), 6, 16, mix_spp=True, exposure=True)
    assert b["spp"].min() >= 1 and b["spp"].max() <= 15
    np.testing.assert_allclose(b["level"], np.log2(b["spp"]) / 10, rtol=1e-6)
    assert np.all(b["exposure"] > 0)
    plain = sample_batch(ts, np.random.default_rng(1), 6, 16, mix_spp=True, exposure=False)
    np.testing.assert_allclose(b["reference"], plain["reference"]
                               * b["exposure"][:, None, None, None], rtol=1e-5)


def test_cli_train_parser():
    from dbench.cli import build_parser, main

    args = build_parser().parse_args(["train", "nca", "--steps", "3", "--minutes", "1"])
    assert args.method == "nca" and args.steps == 3 and args.minutes == 1
    with pytest.raises(SystemExit) as exc:
        main(["train", "unet"])
    assert exc.value.code == 2
    assert main(["train", "nca", "--width-scale", "0.5"]) == 2  # widths: autoencoder only
    assert main(["train", "nca", "--sequences", "3"]) == 2  # the NCA is not recurrent
    assert build_parser().parse_args(["train", "autoencoder"]).sequences is None  # -> 16


# ---------------------------------------------------------------------------------------------
# crops around visible lights, the blend output, training sequences


def _with_light(ts: TrainingSet, scene: int = 1) -> TrainingSet:
    """``ts`` with a 3x3 visible light (black albedo, radiance 20) at row 25, column 5 of one
    scene."""
    ref, alb, noisy = ts.reference.copy(), ts.albedo.copy(), ts.noisy.copy()
    ref[scene, 24:27, 4:7] = 20.0
    noisy[scene, :, 24:27, 4:7] = 20.0
    alb[scene, 24:27, 4:7] = 0.0
    return TrainingSet(noisy=noisy, spp=ts.spp, reference=ref, albedo=alb, normal=ts.normal,
                       depth=ts.depth, scenes=ts.scenes)


def test_light_crops_hold_a_visible_light():
    ts = _with_light(synthetic_training_set(3, 32, (1, 4)))
    px = ts.emitter_pixels()
    assert [len(p) for p in px] == [0, 9, 0]
    b = sample_batch(ts, np.random.default_rng(0), 40, 8, light_fraction=1.0)
    dark = (b["albedo"].max(-1) < 0.02) & (b["reference"].max(-1) > 1.0)
    assert dark.reshape(40, -1).any(1).all()  # every crop shows the light
    uniform = sample_batch(ts, np.random.default_rng(0), 40, 8)
    hits = ((uniform["albedo"].max(-1) < 0.02) & (uniform["reference"].max(-1) > 1.0))
    assert hits.reshape(40, -1).any(1).mean() < 0.3
    # light_fraction = 0 draws exactly what the sampler drew before the option existed
    again = sample_batch(ts, np.random.default_rng(0), 40, 8, light_fraction=0.0)
    for k in uniform:
        assert np.array_equal(uniform[k], again[k])
    from dbench.errors import DbenchInputError
    with pytest.raises(DbenchInputError, match="light_fraction"):
        sample_batch(ts, np.random.default_rng(0), 2, 8, light_fraction=1.5)


def test_light_fraction_without_lights_falls_back_to_uniform_crops():
    ts = synthetic_training_set(2, 32, (1,))
    a = sample_batch(ts, np.random.default_rng(3), 6, 16, light_fraction=0.5)
    b = sample_batch(ts, np.random.default_rng(3), 6, 16)
    for k in a:
        assert np.array_equal(a[k], b[k])


def _assert_onnx_forms_equal_pytorch(net, model, x):
    """The stateful ONNX model (random hidden states) and its stateless form equal ``net``."""
    import onnxruntime as ort

    from dbench.methods.autoencoder.export import stateless_from_stateful

    n, c, h, w = x.shape
    hidden = [torch.randn(s) for s in net.hidden_shapes(n, h, w)]
    with torch.no_grad():
        y, _ = net(x, hidden)
        y0, _ = net(x)
    feeds = {"x": x.numpy(), **{f"h{i + 1}": t.numpy() for i, t in enumerate(hidden)}}
    got = ort.InferenceSession(model.SerializeToString()).run(None, feeds)[0]
    assert np.abs(got - y.numpy()).max() <= 1e-4
    stateless = stateless_from_stateful(model, c, net.enc_widths)
    got0 = ort.InferenceSession(stateless.SerializeToString()).run(None, {"x": x.numpy()})[0]
    assert np.abs(got0 - y0.numpy()).max() <= 1e-4


def test_blend_output_onnx_equals_pytorch_and_keeps_the_input_where_gated():
    from dbench.methods.autoencoder.export import build_onnx
    from dbench.methods.autoencoder.model import RecurrentAE

    torch.manual_seed(0)
    net = RecurrentAE(10, 0.25, blend=True)
    assert net.out.out_channels == 4
    state = {k: v.detach().numpy() for k, v in net.state_dict().items()}
    meta = {"features": "normal,albedo,depth", "in_channels": "10",
            "enc_widths": ",".join(map(str, net.enc_widths))}
    model = build_onnx(state, 10, net.enc_widths, metadata=meta, blend=True)
    assert {p.key: p.value for p in model.metadata_props}["blend"] == "True"
    x = torch.randn(1, 10, 64, 32)
    _assert_onnx_forms_equal_pytorch(net, model, x)
    with torch.no_grad():  # a gate saturated at "keep" returns the input colour
        net.out.weight[3].zero_()
        net.out.bias[3] = 60.0
        y, _ = net(x)
    assert torch.allclose(y, x[:, :3], atol=1e-6)
    with pytest.raises(ValueError, match="exclude"):
        RecurrentAE(10, 0.25, residual=True, blend=True)


def test_level_gate_onnx_equals_pytorch_and_passes_a_converged_input_through():
    from dbench.methods.autoencoder.export import build_onnx
    from dbench.methods.autoencoder.model import RecurrentAE

    torch.manual_seed(0)
    net = RecurrentAE(11, 0.25, residual=True, level_gate=10, gate_init=(-3.0, 1.5))
    with torch.no_grad():  # a non-zero correction (the training init starts at zero)
        net.out.weight.normal_(0.0, 0.05)
    state = {k: v.detach().numpy() for k, v in net.state_dict().items()}
    assert set(state) >= {"level_gate"}
    model = build_onnx(state, 11, net.enc_widths, residual=True, level_gate=10, gate_max=2.0)
    meta = {p.key: p.value for p in model.metadata_props}
    assert meta["level_gate"] == "10" and float(meta["gate_max"]) == 2.0
    x = torch.randn(2, 11, 64, 32)
    x[:, 10] = torch.tensor([0.0, 0.7])[:, None, None]  # two noise levels in one batch
    _assert_onnx_forms_equal_pytorch(net, model, x)
    # the correction is the ungated one times γ(ℓ) = 2 sigmoid(1.5 − 3ℓ), per image
    with torch.no_grad():
        gated = net(x)[0] - x[:, :3]
        net.level_channel = None
        plain = net(x)[0] - x[:, :3]
        net.level_channel = 10
        gamma = 2.0 * torch.sigmoid(1.5 - 3.0 * torch.tensor([0.0, 0.7]))
        assert torch.allclose(gated, plain * gamma[:, None, None, None], rtol=1e-4, atol=1e-6)
        net.level_gate[1] = -60.0  # a closed gate returns the input colour
        assert torch.allclose(net(x)[0], x[:, :3], atol=1e-6)
    with pytest.raises(ValueError, match="level_gate"):
        RecurrentAE(11, 0.25, residual=False, level_gate=10)


def test_pixel_gate_onnx_equals_pytorch_and_gates_the_correction():
    from dbench.methods.autoencoder.export import build_onnx
    from dbench.methods.autoencoder.model import RecurrentAE

    torch.manual_seed(2)
    net = RecurrentAE(10, 0.25, residual=True, pixel_gate=True)
    assert net.out.out_channels == 4
    with torch.no_grad():
        net.out.weight.normal_(0.0, 0.05)
    state = {k: v.detach().numpy() for k, v in net.state_dict().items()}
    model = build_onnx(state, 10, net.enc_widths, residual=True, pixel_gate=True)
    assert {p.key: p.value for p in model.metadata_props}["pixel_gate"] == "True"
    x = torch.randn(1, 10, 64, 32)
    _assert_onnx_forms_equal_pytorch(net, model, x)
    with torch.no_grad():  # a closed gate returns the input colour
        net.out.weight[3].zero_()
        net.out.bias[3] = -60.0
        assert torch.allclose(net(x)[0], x[:, :3], atol=1e-6)
    with pytest.raises(ValueError, match="pixel_gate"):
        RecurrentAE(10, 0.25, pixel_gate=True)


def test_blend_training_ships_a_blend_model(tmp_path):
    from dbench.methods.autoencoder import autoencoder_denoise, reference_denoise

    ts = synthetic_training_set(3, 32, (1, 4))
    r = T.train_autoencoder(ts, _ae_cfg(blend=True, light_fraction=0.5))
    onnx_path, json_path = T.ship_autoencoder(r, tmp_path)
    info = __import__("json").loads(json_path.read_text())
    assert info["blend"] is True and info["residual"] is False
    c, a, n, d = ts.noisy[0, 0, :20, :13], ts.albedo[0, :20, :13], ts.normal[0, :20, :13], \
        ts.depth[0, :20, :13]
    got, _ = autoencoder_denoise(c, a, n, d, weights=onnx_path)
    ref, _ = reference_denoise(c, a, n, d, weights=onnx_path)
    assert np.abs(got - ref).max() <= 1e-4


