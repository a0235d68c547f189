"""A folder's reference judged, not trusted (dbench.datasets.folders.reference): its noise
estimated from what the folder holds or "unknown", never 0; a reference no better than the
noisy input flagged; the reference-noise warning on relMSE over surface pixels."""
import json

import numpy as np
import pandas as pd
import pytest

from dbench.report import tables, verdicts
from dbench.cli import main
from dbench.datasets.folders.load import load_folder, scan_folder
from dbench.datasets.folders.reference import judge_reference, light_mask
from exr_files import write_rgb as _rgb  # tests/exr_files.py

H, W = 24, 40
SIGMA = 0.5  # per-sample standard deviation, relative to the true radiance


def _truth(seed=0):
    return np.random.default_rng(seed).uniform(0.2, 1.0, (H, W, 3))


def _render(truth, spp, seed):
    """The mean of ``spp`` independent samples of standard deviation SIGMA · truth."""
    noise = np.random.default_rng(seed).normal(size=truth.shape)
    return (truth + noise * SIGMA * truth / np.sqrt(spp)).astype(np.float32)


def _folder(path, spps=(4,), ref_spp=256, declare=None, variance=False, truth=None):
    path.mkdir()
    truth = _truth() if truth is None else truth
    for k, spp in enumerate(spps):
        _rgb(path / f"v_{spp:04d}.hdr.exr", _render(truth, spp, 10 + k))
    _rgb(path / "v_ref.hdr.exr", _render(truth, ref_spp, 99))
    if variance:
        _rgb(path / "v_ref.var.exr", (SIGMA * truth) ** 2)
    if declare is not None:
        (path / "dataset.json").write_text(json.dumps({"ref_spp": declare}))
    return path


def test_reference_equal_to_the_noisy_input_is_flagged(tmp_path):
    folder = _folder(tmp_path / "same")
    (folder / "v_ref.hdr.exr").write_bytes((folder / "v_0004.hdr.exr").read_bytes())
    m = load_folder(scan_folder(folder), 4).meta
    assert "numerically equal to the noisy input v_0004.hdr.exr" in m["reference_warning"]
    assert np.isnan(m["ref_rmse"]) and not m["ref_var_known"]  # unknown, not a made-up 0
    assert m["ref_noise_source"].startswith("unknown")


def test_declared_ref_spp_equal_to_the_noisy_spp_is_flagged(tmp_path):
    m = load_folder(scan_folder(_folder(tmp_path / "f", ref_spp=4, declare=4)), 4).meta
    assert "the reference has 4 spp (declared in dataset.json), no more than the noisy " \
           "input's 4" in m["reference_warning"]


def test_a_reference_not_clearly_better_is_flagged_and_a_good_one_is_not(tmp_path):
    poor = load_folder(scan_folder(_folder(tmp_path / "poor", ref_spp=6, declare=6)), 4).meta
    assert "not clearly below the noisy input's" in poor["reference_warning"]
    assert poor["ref_relmse_surface"] >= 0.5 * poor["noisy_relmse_surface"]
    good = load_folder(scan_folder(_folder(tmp_path / "good", declare=256)), 4).meta
    assert "reference_warning" not in good
    # declared spp and the noisy series: the reference's MSE ≈ the noisy MSE · s / (R + s)
    true = np.mean((SIGMA * _truth()) ** 2) / 256
    assert good["ref_rmse"] ** 2 == pytest.approx(true, rel=0.25)
    assert "reference's 256 spp (declared in dataset.json)" in good["ref_noise_source"]


def test_variance_layer_gives_a_finite_estimate(tmp_path):
    folder = _folder(tmp_path / "var", declare=256, variance=True)
    f = load_folder(scan_folder(folder), 4)
    true = (SIGMA * _truth()) ** 2 / 256
    np.testing.assert_allclose(f.reference_var, true, rtol=1e-6)
    assert f.meta["ref_rmse"] == pytest.approx(np.sqrt(true.mean()), rel=1e-6)
    assert f.meta["ref_noise_source"] == "variance image v_ref.var.exr ÷ 256 spp"
    assert "reference_warning" not in f.meta


def test_nothing_known_gives_unknown(tmp_path):
    f = load_folder(scan_folder(_folder(tmp_path / "none")), 4)
    assert f.reference_var is None and not f.meta["ref_var_known"]
    assert np.isnan(f.meta["ref_rmse"])
    assert "one noisy spp" in f.meta["ref_noise_source"]
    # a variance image alone holds σ² per sample: without ref_spp it says why it is unused
    g = load_folder(scan_folder(_folder(tmp_path / "var", variance=True)), 4)
    assert np.isnan(g.meta["ref_rmse"]) and "ref_spp is unknown" in g.meta["ref_noise_source"]


def test_convergence_of_the_series_estimates_the_reference(tmp_path):
    truth = np.random.default_rng(3).uniform(0.2, 1.0, (96, 128, 3))
    series = {s: _render(truth, s, s) for s in (4, 16)}
    names = {4: "a", 16: "b", "ref": "r"}
    ref = _render(truth, 8, 1)
    var, m = judge_reference(reference=ref, spp=4, series=series, names=names, ref_spp=None,
                             ref_spp_from="")
    true = np.mean((SIGMA * truth) ** 2) / 8
    assert m["ref_rmse"] ** 2 == pytest.approx(true, rel=0.2)
    assert m["ref_spp_effective"] == pytest.approx(8, rel=0.2)
    assert "not clearly below" in m["reference_warning"]  # 8 spp against 4
    # progressive renders: the noisy images are the reference's first samples
    samples = [_render(truth, 1, 100 + k) for k in range(64)]
    nested = {s: np.mean(samples[:s], axis=0) for s in (4, 16)}
    var, m = judge_reference(reference=np.mean(samples, axis=0), spp=4, series=nested,
                             names=names, ref_spp=None, ref_spp_from="")
    assert var is None and np.isnan(m["ref_rmse"])
    assert "share its samples" in m["reference_warning"]


def test_surface_pixels_leave_out_lights():
    ref = np.full((4, 6, 3), 0.5)
    ref[0, 0] = 500.0  # a light seen directly
    ref[1, 1] = 0.3  # lit, black in albedo: an emitter with a black BSDF
    albedo = np.full((4, 6, 3), 0.5)
    albedo[1, 1] = 0.0
    surface, rule = light_mask(ref)
    assert not surface[0, 0] and surface.sum() == 23 and "90th percentile" in rule
    surface, rule = light_mask(ref, albedo=albedo)
    assert not surface[1, 1] and surface.sum() == 22 and rule.startswith("albedo")
    emitter = np.zeros((4, 6, 1))
    emitter[2, 2] = 0.5
    surface, rule = light_mask(ref, albedo=albedo, emitter=emitter)
    assert surface.sum() == 23 and not surface[2, 2] and rule == "emitter buffer 0"


def test_warning_uses_relmse_over_surface_pixels(tmp_path):
    """A light seen directly holds the noisy input's squared error: the reference's MSE share
    is far under 10 %, so an MSE comparison says nothing; on relMSE the reference (16 spp
    against 4) holds about a quarter of it, and the report says so."""
    folder = tmp_path / "lamp"
    folder.mkdir()
    truth = _truth()
    truth[5, 7] = 1000.0  # a light, its edge pixel 30 % off in the noisy input
    noisy, ref = _render(truth, 4, 1), _render(truth, 16, 2)
    noisy[5, 7], ref[5, 7] = 700.0, 1000.0
    var = (SIGMA * truth) ** 2
    var[5, 7] = 0.0  # the light's inside is noise-free
    _rgb(folder / "v_0004.hdr.exr", noisy)
    _rgb(folder / "v_ref.hdr.exr", ref)
    _rgb(folder / "v_ref.var.exr", var)
    (folder / "dataset.json").write_text(json.dumps({"ref_spp": 16}))
    out = tmp_path / "run"
    assert main(["run", "--method", "noisy", "--scene", str(folder), "--spp", "4",
                 "--repeats", "1", "--quiet", "--out", str(out)]) == 0
    row = pd.read_csv(out / "metrics.csv").iloc[0]
    assert row.ref_rmse ** 2 / row.rmse ** 2 < 0.01  # the light hid it from MSE
    assert row.ref_relmse_surface / row.relmse_surface > 0.1
    report = (out / "report.md").read_text(encoding="utf-8")
    assert "## Reference noise" in report and "relMSE over surface pixels" in report
    flagged = verdicts.ref_noise_frame(tables.cells_frame([{**row.to_dict(), "status": "ok"}]))
    assert list(flagged.share_on) == ["relmse_surface"]


@pytest.mark.parametrize("variance", [False, True])
def test_a_reference_noisier_than_declared_is_flagged(tmp_path, variance):
    """A 4-spp reference declared at 4096 spp (with or without a variance image): the
    high-pass comparison, which trusts no declaration, finds its noise; an honest 4096-spp
    reference of a textured image is not flagged."""
    truth = _truth(3)  # per-pixel random: the scene's detail is all high-frequency
    lying = load_folder(_folder(tmp_path / "lying", ref_spp=4, declare=4096,
                                variance=variance, truth=truth), spp=4)
    warning = lying.meta.get("reference_warning", "")
    assert "noisier than its estimate" in warning and "render of about" in warning, warning
    # the contradicted estimate is not kept: the reference's error is unknown, so no
    # reference_var makes the unbiased figures look corrected
    assert lying.meta["ref_noise_source"].startswith("unknown: the high-pass check")
    assert np.isnan(lying.meta["ref_rmse"]) and lying.reference_var is None
    honest = load_folder(_folder(tmp_path / "honest", ref_spp=4096, declare=4096,
                                 variance=variance, truth=truth), spp=4)
    assert "reference_warning" not in honest.meta, honest.meta.get("reference_warning")
    assert np.isfinite(honest.meta["ref_rmse"]) and honest.reference_var is not None


def test_unbiased_figures_are_unknown_when_the_reference_noise_is(tmp_path):
    """A reference whose noise nothing gives: rmse_unbiased and relmse_unbiased are empty in
    metrics.csv (never the raw figures passed off as unbiased), the report states them as
    unknown and ranks on the raw metric instead; a reference with its variance image keeps
    finite unbiased figures below the raw ones."""
    out = tmp_path / "run"
    assert main(["run", "--method", "noisy", "--scene", str(_folder(tmp_path / "none")),
                 "--spp", "4", "--repeats", "1", "--quiet", "--rank-by", "rmse_unbiased",
                 "--out", str(out)]) == 0
    row = pd.read_csv(out / "metrics.csv").iloc[0]
    assert np.isfinite(row.rmse) and np.isfinite(row.relmse)
    for col in ("rmse_unbiased", "relmse_unbiased", "rmse_unbiased_ci", "ref_rmse"):
        assert np.isnan(row[col]), col
    report = (out / "report.md").read_text(encoding="utf-8")
    assert "Ranking by rmse (lower is better)" in report
    assert "unknown (an empty cell) where v_r is" in report
    known = tmp_path / "known"
    assert main(["run", "--method", "noisy", "--scene",
                 str(_folder(tmp_path / "var", declare=256, variance=True)), "--spp", "4",
                 "--repeats", "1", "--quiet", "--out", str(known)]) == 0
    row = pd.read_csv(known / "metrics.csv").iloc[0]
    assert 0 < row.rmse_unbiased < row.rmse and 0 < row.relmse_unbiased < row.relmse


def test_a_small_reference_noisier_than_declared_is_still_flagged(tmp_path):
    """At 16 × 16 px 8-px tiles are too few for the high-pass comparison: 4-px tiles serve, and
    a 4-spp reference declared at 4096 is flagged; at 8 × 8 nothing can be measured, and the
    estimate says it was not checked instead of standing as a fact."""
    truth = np.random.default_rng(3).uniform(0.2, 1.0, (16, 16, 3))
    lying = load_folder(_folder(tmp_path / "lying", ref_spp=4, declare=4096, truth=truth),
                        spp=4)
    assert "noisier than its estimate" in lying.meta.get("reference_warning", ""), lying.meta
    honest = load_folder(_folder(tmp_path / "honest", ref_spp=4096, declare=4096, truth=truth),
                         spp=4)
    assert "reference_warning" not in honest.meta, honest.meta.get("reference_warning")
    tiny = load_folder(_folder(tmp_path / "tiny", ref_spp=4, declare=4096, truth=truth[:8, :8]),
                       spp=4)
    assert "not checked against the noisy input" in tiny.meta["ref_noise_source"], tiny.meta


def test_without_an_emitter_buffer_the_surface_metrics_leave_out_the_checks_lights(tmp_path):
    """The surface metrics are over the pixels the report lists as surface pixels (the
    reference check's light_mask), not over every pixel: a bright light in view is left out."""
    from dbench.run.scoring import judge_frame

    truth = _truth()
    truth[2:6, 3:9] = 500.0  # a light seen directly: far above 4x the 90th percentile
    _folder(tmp_path / "f", spps=(4, 16), truth=truth, declare=256)
    frame = load_folder(scan_folder(tmp_path / "f"), 4, ["color", "reference"])
    surface, _ = light_mask(frame.reference)
    assert frame.emitter is None and frame.meta["surface_pixels"].startswith(
        f"{int(surface.sum())} of {H * W}: ")
    np.testing.assert_array_equal(frame.judged_lights[..., 0], ~surface)
    assert (~surface).sum() == 24  # the light's 4 x 6 pixels
    v = judge_frame(frame.color, frame).values
    on_surface = np.sqrt(np.mean((frame.color - frame.reference)[surface] ** 2))
    assert v["rmse_surface"] == pytest.approx(on_surface, rel=1e-6)
    assert v["rmse"] > 2 * v["rmse_surface"]  # the light's error is in the whole image only
