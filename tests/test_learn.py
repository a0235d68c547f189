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
# losses (spec/autoencoder.md §6.4)


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
    from dbench.datasets import scenes

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
    """spec/autoencoder.md §6.5: 20 steps on a synthetic set reduce the loss by >= 20 %."""
    ts = synthetic_training_set(4, 32, (1,))
    r = T.train_autoencoder(ts, _ae_cfg(steps=20, batch=4, lr=3e-3, lr_decay_at=(),
                                        residual=False))
    assert np.mean(r.losses[-4:]) <= 0.8 * np.mean(r.losses[:4])


def test_sequence_training_path_trains_the_recurrent_weights():
    from dbench.methods.autoencoder.model import RecurrentAE

    ts = synthetic_training_set(2, 32, (1, 4))
    torch.manual_seed(0)
    net = RecurrentAE(10, 0.25)
    with torch.no_grad():
        for lvl, conv in enumerate(net.rec_b):
            conv.weight[:, net.enc_widths[lvl]:] = 0.0
    before = net.rec_b[0].weight.detach().clone()

    def seq_batch(rng):
        b = sample_batch(ts, rng, 2, 32)
        # a 3-frame static sequence: the same crop with fresh noise per frame
        frames = [dict(b, noisy=np.maximum(b["reference"] * (1 + 0.5 * rng.standard_normal(
            b["reference"].shape)), 0).astype(np.float32)) for _ in range(3)]
        return {k: np.stack([f[k] for f in frames], 1) for k in b if k != "spp"}

    curve = T.train_autoencoder_sequences(net, seq_batch, _ae_cfg(steps=2))
    assert len(curve) == 2 and all(np.isfinite(curve))
    e = net.enc_widths[0]
    assert not torch.equal(net.rec_b[0].weight[:, e:], before[:, e:])


def test_ship_and_load_trained_weights(tmp_path):
    from dbench import methods
    from dbench.data import Frame

    ts = synthetic_training_set(3, 32, (1, 4))
    tr, va = T.split(ts, 1)
    nca = T.train_nca(tr, _nca_cfg(color_encoding="log1p_demodulated", linear_weight=0.1),
                      validation=va)
    assert "linear" in nca.parts[-1]
    onnx_path, json_path = T.ship_nca(nca, tmp_path)
    info = __import__("json").loads(json_path.read_text())
    assert info["parameters"] == 360 and info["data"]["hash"] == tr.hash
    assert info["color_encoding"] == "log1p_demodulated"
    assert info["losses"]["steps_done"] == 6 and "loss" in info["losses"]["validation"]
    ae = T.train_autoencoder(tr, _ae_cfg(), validation=va)
    ae_onnx, ae_json = T.ship_autoencoder(ae, tmp_path)
    f = Frame(color=ts.noisy[0, 0, :20, :13], albedo=ts.albedo[0, :20, :13],
              normal=ts.normal[0, :20, :13], depth=ts.depth[0, :20, :13])
    assert methods.get("nca", weights=str(onnx_path)).denoise(f).shape == (20, 13, 3)
    assert methods.get("autoencoder", weights=str(ae_onnx)).denoise(f).shape == (20, 13, 3)
    from dbench.methods.nca import nca_denoise, reference_denoise

    a = nca_denoise(f.color, f.normal, f.albedo, weights=onnx_path)
    b = reference_denoise(f.color, f.normal, f.albedo, weights=onnx_path)
    assert np.abs(a - b).max() <= 1e-4


def test_cli_train_parser():
    from dbench.cli import build_parser, main

    args = build_parser().parse_args(["train", "nca", "--steps", "3", "--minutes", "1"])
    assert args.method == "nca" and args.steps == 3 and args.minutes == 1
    with pytest.raises(SystemExit) as exc:
        main(["train", "unet"])
    assert exc.value.code == 2
    assert main(["train", "nca", "--width-scale", "0.5"]) == 2  # widths: autoencoder only
