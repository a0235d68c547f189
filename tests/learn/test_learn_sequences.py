"""dbench.learn on sequences: training sequences, sequence sets and their fine-tuning, the NCA's
step-count selection, the relative linear loss."""
import numpy as np
import pytest
import torch
from dbench.learn import losses as L
from dbench.learn import train as T
from dbench.learn.dataset import synthetic_training_set

from test_learn import _nca_cfg  # noqa: E402 - the same folder


def test_training_sequence_is_the_training_scene_with_a_moving_camera():
    from dbench.datasets.mitsuba_env import mitsuba
    from dbench.learn.scenes import build_training_dict, training_sequence

    mi = mitsuba()
    seq = training_sequence(4)
    assert seq.name == "train-seq-004" and seq.n_frames == 8
    d0 = seq.frame_dict(mi, 16, 0)
    steady = build_training_dict(mi, 16, 4)
    assert set(d0) - {"integrator"} == set(steady)
    m0 = np.array(d0["sensor"]["to_world"].matrix)
    assert np.allclose(m0, np.array(steady["sensor"]["to_world"].matrix), atol=1e-5)
    origins = np.array([seq.camera(i)[0] for i in range(8)])
    step = np.linalg.norm(np.diff(origins, axis=0), axis=1)
    assert (step > 1e-3).all() and (step < 0.2).all()  # moves every frame, a little
    assert seq.camera(3) == training_sequence(4).camera(3)


def _tiny_sequence_set(s=2, p=2, f=8, res=32):
    from dbench.learn.dataset import SequenceSet

    rng = np.random.default_rng(0)
    ref = rng.uniform(0.1, 1.0, (s, f, res, res, 3)).astype(np.float32)
    noisy = np.maximum(ref[:, None] * (1 + 0.5 * rng.standard_normal((s, p, f, res, res, 3))),
                       0).astype(np.float32)
    alb = np.full((s, p, f, res, res, 3), 0.5, np.float32)
    nrm = np.zeros((s, p, f, res, res, 3), np.float32)
    nrm[..., 2] = 1
    dep = np.ones((s, p, f, res, res, 1), np.float32)
    return SequenceSet(noisy=noisy, spp=(1, 4)[:p], reference=ref, albedo=alb, normal=nrm,
                       depth=dep, scenes=[f"seq{i}" for i in range(s)])


def test_sequence_set_checks_and_batches():
    from dbench.errors import DbenchInputError
    from dbench.learn.dataset import SequenceSet, sample_sequence_batch

    ss = _tiny_sequence_set()
    b = sample_sequence_batch(ss, np.random.default_rng(0), 3, 16, 7)
    assert b["noisy"].shape == (3, 7, 16, 16, 3) and b["depth"].shape == (3, 7, 16, 16, 1)
    b2 = sample_sequence_batch(ss, np.random.default_rng(0), 3, 16, 7)
    assert all(np.array_equal(b[k], b2[k]) for k in b)
    with pytest.raises(DbenchInputError, match="frames"):
        sample_sequence_batch(ss, np.random.default_rng(0), 1, 16, 9)
    with pytest.raises(DbenchInputError, match="albedo"):
        SequenceSet(noisy=ss.noisy, spp=ss.spp, reference=ss.reference, albedo=ss.albedo[:, :1],
                    normal=ss.normal, depth=ss.depth, scenes=ss.scenes)
    assert ss.hash == _tiny_sequence_set().hash


def test_sequence_finetuning_is_reproducible_and_uses_the_state():
    from dbench.methods.autoencoder.model import RecurrentAE

    ss = _tiny_sequence_set()
    steady = synthetic_training_set(2, 32, (1, 4))
    cfg = T.AESequenceConfig(steps=4, batch=1, crop=32, frames=3, steady_batch=2,
                             steady_crop=32)

    def run():
        torch.manual_seed(0)
        net = RecurrentAE(10, 0.25)
        with torch.no_grad():
            for lvl, conv in enumerate(net.rec_b):
                conv.weight[:, net.enc_widths[lvl]:] = 0.0
        summary = T.finetune_autoencoder_sequences(net, ss, cfg, ("normal", "albedo", "depth"),
                                                   steady=steady)
        return net, summary

    net, a = run()
    _, b = run()
    assert a["loss_curve"] == b["loss_curve"] and a["steps_done"] == 4
    assert "seq_temporal" in a["final_parts"] and "steady_l1" in a["final_parts"]
    e = net.enc_widths[0]
    assert net.rec_b[0].weight[:, e:].abs().sum() > 0  # the recurrent half learned
    v = T.validate_autoencoder_sequences(net, ss, ("normal", "albedo", "depth"), frames=3)
    assert v["loss_state_carried"] != v["loss_state_reset"]


def test_step_count_selection_worst_case_first():
    ts = synthetic_training_set(3, 32, (1, 4))
    tr, va = T.split(ts, 1)
    r = T.train_nca(tr, _nca_cfg(steps=4, relative_weight=1.0, light_fraction=0.25))
    k, table = T.select_iterations(r.model, va, (1, 2, 3), by="worst")
    assert set(table) == {"1", "2", "3"} and all(set(v) == {"mean", "worst"}
                                                 for v in table.values())
    assert table[str(k)]["worst"] == min(v["worst"] for v in table.values())
    assert all(v["worst"] >= v["mean"] for v in table.values())
    k_mean, _ = T.select_iterations(r.model, va, (1, 2, 3), by="mean")
    assert table[str(k_mean)]["mean"] == min(v["mean"] for v in table.values())
    with pytest.raises(ValueError, match="worst"):
        T.select_iterations(r.model, va, (1,), by="median")


def test_step_count_selection_per_sample_count_and_lookup(tmp_path):
    """select_iterations(per_spp=True) picks, for every sample count of the held-out set, the
    count with the lowest worst-case relMSE ratio; the shipped table then gives a frame's step
    count by the nearest tabulated spp in log2 (unknown spp: the 1-spp entry)."""
    from dbench.methods.nca import default_iterations, nca_denoise

    ts = synthetic_training_set(3, 32, (1, 4))
    tr, va = T.split(ts, 1)
    cfg = _nca_cfg(steps=4, relative_weight=1.0)
    r = T.train_nca(tr, cfg)
    chosen, tables = T.select_iterations(r.model, va, (1, 2, 3), metric="relmse", per_spp=True)
    assert set(chosen) == {1, 4} and set(tables) == {"1", "4"}
    for n, k in chosen.items():
        assert tables[str(n)][str(k)]["worst"] == min(v["worst"] for v in tables[str(n)].values())
    with pytest.raises(ValueError, match="metric"):
        T.select_iterations(r.model, va, (1,), metric="psnr")
    # ship with a hand-made table and look the counts up
    r.data["iterations_by_spp"] = {1: 3, 16: 2, 1024: 1}
    onnx_path, json_path = T.ship_nca(r, tmp_path)
    assert __import__("json").loads(json_path.read_text())["iterations_by_spp"] == \
        {"1": 3, "16": 2, "1024": 1}
    for spp, k in ((None, 3), (1, 3), (3, 3), (5, 2), (16, 2), (100, 2), (200, 1), (4096, 1)):
        assert default_iterations(onnx_path, spp) == k, spp
    f = va.noisy[0, 0]
    for spp in (1, 16, 1024):  # None means the table's count for the frame's spp
        k = default_iterations(onnx_path, spp)
        np.testing.assert_array_equal(
            nca_denoise(f, va.normal[0], va.albedo[0], weights=onnx_path, spp=spp),
            nca_denoise(f, va.normal[0], va.albedo[0], iterations=k, weights=onnx_path, spp=spp))


def test_relative_linear_mse():
    t = torch.log1p(torch.full((2, 3, 4, 4), 1.0))
    noisy = torch.full((2, 3, 4, 4), 2.0)  # input error 1 per pixel
    assert float(L.relative_linear_mse(t, t, noisy)) == 0.0
    p = torch.log1p(torch.full((2, 3, 4, 4), 1.5))  # output error 0.5: a quarter of the input's
    assert abs(float(L.relative_linear_mse(p, t, noisy, eps=0.0)) - 0.25) < 1e-6
    # each crop counts relative to its own input: halving the error on a crop whose input was
    # 10x worse weighs the same as halving it on the other
    noisy2 = noisy.clone()
    noisy2[1] = 1.0 + 10.0
    p2 = p.clone()
    p2[1] = torch.log1p(torch.tensor(1.0 + 5.0))
    assert abs(float(L.relative_linear_mse(p2, t, noisy2, eps=0.0)) - 0.25) < 1e-6


def test_sequence_set_renders_matched_frames(renderer, tmp_path):
    """Two tiny training sequences through the real renderer and cache: shapes, finite values,
    a G-buffer per spp (matched to that spp's samples), references shared, a cached rebuild."""
    from dbench.datasets.cache import Cache
    from dbench.learn.dataset import build_sequence_set, split_sequences

    cache = Cache(tmp_path)
    kw = dict(n_sequences=2, n_frames=2, res=32, spp=(1, 2), ref_spp=16, cache=cache,
              progress=False)
    ss = build_sequence_set(**kw)
    assert ss.noisy.shape == (2, 2, 2, 32, 32, 3) and ss.reference.shape == (2, 2, 32, 32, 3)
    assert ss.depth.shape == (2, 2, 2, 32, 32, 1)
    for a in (ss.noisy, ss.reference, ss.albedo, ss.normal, ss.depth):
        assert np.isfinite(a).all()
    assert ss.depth.max() <= 1.0 and ss.scenes[0].startswith("train-seq-")
    assert not np.array_equal(ss.noisy[:, 0, 1], ss.noisy[:, 0, 0])  # the camera moved
    assert ss.hash == build_sequence_set(**kw).hash  # read back from the cache
    train, held = split_sequences(ss, 1)
    assert train.scenes == ss.scenes[:1] and held.scenes == ss.scenes[1:]
