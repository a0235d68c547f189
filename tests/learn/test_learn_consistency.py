"""The autoencoder's consistency stage (stage 3), its relMSE-relative loss, resuming from shipped
weights, and the feature buffers' sample count following the colour's."""
import json

import numpy as np
import pytest
import torch

from dbench.learn import losses as L
from dbench.learn import train as T
from dbench.learn.dataset import SequenceSet, synthetic_training_set

torch.set_num_threads(1)

FEATURES = ("normal", "albedo", "depth")


def _sequences(s=2, f=8, res=32) -> SequenceSet:
    rng = np.random.default_rng(1)
    ref = rng.uniform(0.1, 1.0, (s, f, res, res, 3)).astype(np.float32)
    noisy = np.maximum(ref[:, None] * (1 + 0.5 * rng.standard_normal((s, 2, f, res, res, 3))),
                       0).astype(np.float32)
    nrm = np.zeros((s, 2, f, res, res, 3), np.float32)
    nrm[..., 2] = 1
    return SequenceSet(noisy=noisy, spp=(1, 4), reference=ref,
                       albedo=np.full((s, 2, f, res, res, 3), 0.5, np.float32), normal=nrm,
                       depth=np.ones((s, 2, f, res, res, 1), np.float32),
                       scenes=[f"seq{i}" for i in range(s)])


def test_relative_loss_in_relmse():
    """metric "relmse": each pixel's squared error divided by (reference² + 1e-2), as
    dbench.metrics.pixel.relmse, so a bright pixel's error weighs like a dark one's relative
    error; "mse" weighs the bright pixel's absolute error."""
    from dbench.metrics.pixel import relmse

    t_lin = torch.ones((1, 3, 2, 2))
    t_lin[..., 0, 0] = 10.0  # one bright pixel
    noisy = t_lin * 1.2  # 20 % too bright everywhere
    out = t_lin.clone()
    out[..., 0, 0] = 10.0 * 1.1  # the bright pixel halves its relative error; the rest exact
    p, t = torch.log1p(out), torch.log1p(t_lin)
    to_np = lambda x: x[0].permute(1, 2, 0).numpy()  # noqa: E731
    want = relmse(to_np(out), to_np(t_lin)) / relmse(to_np(noisy), to_np(t_lin))
    got = float(L.relative_linear_mse(p, t, noisy, eps=0.0, metric="relmse"))
    assert got == pytest.approx(want, rel=1e-5)
    mse_form = float(L.relative_linear_mse(p, t, noisy, eps=0.0))
    assert mse_form == pytest.approx(0.25 / 1.03, rel=1e-5)  # (1 / 4) / ((4 + 3 · 0.04) / 4)
    assert got < mse_form  # relMSE counts the three exact dim pixels as much as the bright one
    with pytest.raises(ValueError, match="metric"):
        L.relative_linear_mse(p, t, noisy, metric="l1")


def _tiny_shipped(tmp_path):
    ts = synthetic_training_set(3, 32, (1, 4))
    tr, va = T.split(ts, 1)
    r = T.train_autoencoder(tr, T.AEConfig(steps=3, batch=2, crop=32, width_scale=0.25,
                                           features=FEATURES), validation=va)
    return r, tr, va, T.ship_autoencoder(r, tmp_path)


def test_resume_from_shipped_weights_restores_model_and_record(tmp_path):
    r, _, _, (onnx_path, json_path) = _tiny_shipped(tmp_path)
    back = T.resume_autoencoder(onnx_path)
    for (k, a), (_, b) in zip(r.model.state_dict().items(), back.model.state_dict().items()):
        assert torch.equal(a, b), k
    assert back.config == r.config and back.data["hash"] == r.data["hash"]
    # the resumed result stands on the shipped run's stage-1 record
    assert back.summary()["final_train_loss"] == pytest.approx(r.summary()["final_train_loss"])
    from dbench.errors import DbenchInputError

    with pytest.raises(DbenchInputError, match="json"):
        T.resume_autoencoder(tmp_path / "missing.onnx")


def test_consistency_stage_is_reproducible_and_uses_its_loss(tmp_path):
    _, tr, va, (onnx_path, _) = _tiny_shipped(tmp_path)
    ss = _sequences()
    cfg = T.AEConsistencyConfig(steps=4)
    scfg_kw = dict(batch=1, crop=32, frames=3, steady_batch=2, steady_crop=32)

    def run():
        res = T.resume_autoencoder(onnx_path)
        before = [p.detach().clone() for p in res.model.parameters()]
        import dbench.learn.train_autoencoder as TA

        # the tiny schedule: the stage's own settings are kept, crops and batches shrunk
        orig = TA.AESequenceConfig
        TA.AESequenceConfig = lambda **kw: orig(**{**kw, **scfg_kw})
        try:
            stage = T.consistency_stage(res.model, ss, tr, cfg, res.config)
        finally:
            TA.AESequenceConfig = orig
        moved = any(not torch.equal(a, b) for a, b in zip(before, res.model.parameters()))
        return res, stage, moved

    res, a, moved = run()
    _, b, _ = run()
    assert a["loss_curve"] == b["loss_curve"] and a["steps_done"] == 4 and moved
    assert a["config"]["relative_metric"] == "relmse" and a["config"]["relative_eps"] == 1e-6
    assert a["config"]["sequence_schedule"]["lr"] == cfg.lr
    assert "steady_relative" in a["final_parts"] and "seq_relative" in a["final_parts"]
    assert a["steady_data"]["hash"] == tr.hash
    res.data["consistency_stage"] = a
    _, json_path = T.ship_autoencoder(res, tmp_path / "out")
    info = json.loads(json_path.read_text())
    assert info["data"]["consistency_stage"]["steps_done"] == 4
    assert info["loss_curve"]  # the stage-1 curve of the run it resumed


def test_from_weights_is_refused_where_it_does_not_apply(tmp_path):
    from dbench.cli import main

    assert main(["train", "nca", "--from-weights", "x.onnx"]) == 2
    assert main(["train", "autoencoder", "--from-weights", str(tmp_path / "none.onnx")]) == 2
    assert main(["train", "autoencoder", "--from-weights", __file__, "--steps", "3"]) == 2
    from dbench.learn.dataset import build_training_set

    with pytest.raises(ValueError, match="features_with"):
        build_training_set(features_with="middle")


# ---------------------------------------------------------------------------------------------
# feature buffers at the colour's sample count


def test_feature_spp_follows_the_colour_and_enters_the_identity_above_the_default():
    from dbench import datasets
    from dbench.run import sweep as S
    from dbench.datasets.render import DEFAULT_FEATURE_SPP, feature_spp

    assert [feature_spp(n) for n in (1, 64, 65, 1024)] == [64, 64, 65, 1024]
    assert DEFAULT_FEATURE_SPP == 64
    assert datasets.feature_identity("cornell", 16) == {}
    assert datasets.feature_identity("cornell", 256) == {"feature_spp": 256}
    assert datasets.feature_identity("orbit", 256) == {}  # sequences: matched G-buffer
    cfg = S.SweepConfig(methods=["noisy"], scenes=["cornell"], spp=[16, 256], res=16)
    scene = cfg.scene("cornell")
    low = S.cell_identity(cfg, scene, 16, "noisy", "fp")
    high = S.cell_identity(cfg, scene, 256, "noisy", "fp")
    assert "feature_spp" not in low and high["feature_spp"] == 256


def test_frames_render_their_features_at_the_colour_spp(renderer, tmp_path):
    from dbench import datasets
    from dbench.datasets.cache import Cache

    cache = Cache(tmp_path)
    lo = datasets.load("cornell", spp=4, res=8, needs={"color", "albedo"}, cache=cache,
                       progress=False)
    hi = datasets.load("cornell", spp=128, res=8, needs={"color", "albedo"}, cache=cache,
                       progress=False)
    assert lo.meta["feature_spp"] == 64 and hi.meta["feature_spp"] == 128
    assert "features" in hi.meta["rendered"]  # not the 64-spp entry of the first load
    again = datasets.load("cornell", spp=128, res=8, needs={"color", "albedo"}, cache=cache,
                          progress=False)
    assert "features" in again.meta["cache_hits"]
    np.testing.assert_array_equal(again.albedo, hi.albedo)
