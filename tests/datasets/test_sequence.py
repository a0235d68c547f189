"""Sequence datasets, camera projection, motion vectors, gradient frames and the sequence runner."""
import math

import numpy as np
import pytest

from dbench import datasets
from dbench import synthetic
from dbench.report import sequence_figures
from dbench.run import sequence_run as BS
from dbench.speed import sequence as speed_sequence
from dbench.data import Frame, Sequence
from dbench.datasets.scenes import catalogue as scenes
from dbench.datasets.sequence import load as S
from dbench.errors import DbenchInputError

RES = 16


@pytest.fixture(scope="module")
def seq_cache(tmp_path_factory):
    from dbench.datasets import Cache
    return Cache(tmp_path_factory.mktemp("seq-cache"))


@pytest.fixture(scope="module")
def flicker(renderer, seq_cache):
    # frames 14 … 17 would need rendering from 0; the switch is at 16, so render 18 tiny frames
    return datasets.load("flicker", spp=1, res=RES, frames=18, ref_spp=16, cache=seq_cache,
                         progress=False)


@pytest.fixture(scope="module")
def orbit(renderer, seq_cache):
    return datasets.load("orbit", spp=1, res=24, frames=4, ref_spp=16, cache=seq_cache,
                         progress=False)


# -- data types and catalogue -------------------------------------------------------------------

def test_sequence_dataclass():
    f = Frame(color=np.zeros((3, 4, 3)))
    s = Sequence([f, f])
    assert len(s) == 2 and s.shape == (3, 4) and s.kind == "sequence" and s[1] is f
    assert not s.has("motion")
    with pytest.raises(DbenchInputError, match="frames"):
        Sequence([])
    with pytest.raises(DbenchInputError, match=r"frames\[1\]"):
        Sequence([f, Frame(color=np.zeros((3, 5, 3)))])
    with pytest.raises(DbenchInputError, match="motion"):
        Frame(color=np.zeros((3, 4, 3)), motion=np.zeros((3, 4, 3)))


def test_sequence_scenes_are_in_the_catalogue():
    for name in ("orbit", "flicker", "mirror-pan"):
        sc = scenes.get(name)
        assert sc.kind == "sequence" and name in datasets.available_scenes()
        assert {"motion", "gradient", "reference"} <= set(sc.provides)
        assert 32 <= sc.n_frames <= 60
    assert scenes.get("flicker").events == {"light_change": S.FLICKER_SWITCH}


def test_load_rejects_bad_arguments(renderer, seq_cache):
    with pytest.raises(DbenchInputError, match="frames"):
        datasets.load("orbit", spp=1, res=8, frames=500, cache=seq_cache)
    with pytest.raises(DbenchInputError, match="needs"):
        datasets.load("orbit", spp=1, res=8, frames=2, needs={"bogus"}, cache=seq_cache)
    # sequences provide per-frame statistics; a bad transform is refused before rendering
    with pytest.raises(DbenchInputError, match="transform"):
        datasets.load("orbit", spp=1, res=8, frames=2, needs={"stats"}, transform="nope",
                      cache=seq_cache)
    with pytest.raises(DbenchInputError, match="gbuffer"):
        S.load_sequence("orbit", spp=1, res=8, frames=2, cache=seq_cache, gbuffer="fancy")


# -- camera geometry ------------------------------------------------------------------------------

def test_look_at_matches_mitsuba(renderer):
    mi = renderer
    for o, t in (((1, 2, 3), (0, 0, 0)), ((0.3, 0.1, 3.7), (0, -0.2, 0))):
        m = np.array(mi.ScalarTransform4f().look_at(origin=list(o), target=list(t),
                                                    up=[0, 1, 0]).matrix)
        np.testing.assert_allclose(S.look_at_matrix(o, t), m, atol=1e-6)


def test_projection_round_trip():
    cam = {"to_world": S.look_at_matrix((0.2, 0.3, 4.0), (0, 0, 0)).tolist(), "fov": 40.0,
           "fov_axis": "x", "width": 64, "height": 48}
    m = np.array(cam["to_world"])
    t = math.tan(math.radians(40.0) / 2)
    yy, xx = np.mgrid[0:48, 0:64] + 0.5  # pixel centres (continuous Mitsuba coordinates)
    u, v = xx / 64, yy / 48
    d_cam = np.stack([(0.5 - u) / 0.5 * t, (0.5 - v) / 0.5 * t * 48 / 64, np.ones_like(u)], -1)
    pts = (d_cam * 3.0) @ m[:3, :3].T + m[:3, 3]
    p, cz = S.project(pts, cam)
    np.testing.assert_allclose(p[..., 0], xx - 0.5, atol=1e-4)
    np.testing.assert_allclose(p[..., 1], yy - 0.5, atol=1e-4)
    assert (cz > 0).all()


def test_rendered_positions_project_into_their_own_pixels(flicker):
    """Matched 1-spp G-buffer: every hit's position lies inside the pixel it was sampled in."""
    f = flicker[3]
    p, cz = S.project(f.position, f.meta["camera"])
    yy, xx = np.mgrid[0:RES, 0:RES]
    hit = f.depth[..., 0] > 0
    assert hit.mean() > 0.7
    assert np.abs(p[..., 0] - xx)[hit].max() <= 0.5 + 1e-3
    assert np.abs(p[..., 1] - yy)[hit].max() <= 0.5 + 1e-3


def test_motion_vectors_point_to_the_previous_position(orbit):
    """Each pixel's motion is that of the surface point seen through its centre: the point
    where the centre ray meets the tangent plane of the pixel's (jittered) sample, projected
    with the previous camera (exact on the room's flat walls)."""
    prev, cur = orbit[2], orbit[3]
    cam, cam_prev = cur.meta["camera"], prev.meta["camera"]
    h, w = cur.depth.shape[:2]
    yy, xx = np.mgrid[0:h, 0:w]
    to_world = np.asarray(cam["to_world"], np.float64)
    t = np.tan(np.radians(cam["fov"]) / 2.0)
    sx, sy = (t, t * h / w) if cam.get("fov_axis", "x") == "x" else (t * w / h, t)
    d_cam = np.stack([(0.5 - (xx + 0.5) / w) * 2 * sx, (0.5 - (yy + 0.5) / h) * 2 * sy,
                      np.ones((h, w))], -1)
    d = d_cam @ to_world[:3, :3].T
    o = to_world[:3, 3]
    n = cur.normal.astype(np.float64)
    denom = np.sum(n * d, -1)
    ok = np.isfinite(cur.motion[..., 0]) & (np.abs(denom) > 0.2)
    along = np.sum(n * (cur.position - o), -1) / np.where(ok, denom, 1.0)
    centre_point = o + along[..., None] * d
    p_prev, _ = S.project(centre_point, cam_prev)
    expected = p_prev - np.stack([xx, yy], -1)
    err = np.linalg.norm(cur.motion - expected, axis=-1)[ok]
    assert ok.mean() > 0.6
    # first order in the jitter: the motion field's slope times at most half a pixel
    assert np.median(err) < 0.01 and np.percentile(err, 90) < 0.05
    jittered = S.project(cur.position, cam_prev)[0] - np.stack([xx, yy], -1)  # the old form
    assert np.median(np.linalg.norm(jittered - expected, axis=-1)[ok]) > 0.1
    assert np.isnan(cur.motion[cur.depth[..., 0] == 0]).all()


def test_motion_vectors_carry_no_sample_jitter(flicker, orbit):
    """The motion of the surface point, not of the 1-spp sample's place in its pixel: a static
    camera gives exactly 0 (the jittered form gave offsets of up to half a pixel), and on the
    moving camera neighbouring pixels of the back wall move alike."""
    f = flicker[5]
    hit = f.depth[..., 0] > 0
    assert hit.mean() > 0.7
    np.testing.assert_array_equal(f.motion[hit], 0.0)
    cur = orbit[3]
    m = cur.motion[..., 0]
    both = np.isfinite(m[:, 1:]) & np.isfinite(m[:, :-1])
    step = np.abs(np.diff(m, axis=1))[both]
    assert np.median(step) < 0.02  # jitter alone would make it about 0.4


# -- rendering --------------------------------------------------------------------------------------

def test_frames_carry_every_buffer_and_the_camera(flicker):
    f = flicker[5]
    for name, c in (("color", 3), ("albedo", 3), ("normal", 3), ("depth", 1), ("position", 3),
                    ("motion", 2), ("gradient", 3), ("emission", 3), ("reference", 3)):
        assert getattr(f, name).shape == (RES, RES, c), name
    cam = f.meta["camera"]
    assert cam["fov"] == pytest.approx(39.3) and np.array(cam["to_world"]).shape == (4, 4)
    assert flicker.meta["events"]["light_change"] == S.FLICKER_SWITCH
    np.testing.assert_array_equal(flicker[0].gradient, flicker[0].color)


def test_reshaded_samples_are_the_brightest_and_reuse_the_previous_random_numbers(flicker):
    """docs/temporal.md §2: one re-shaded sample per 3×3 stratum of frame i−1, its brightest hit
    pixel, traced again with frame i−1's random numbers (static camera here, so with unchanged
    lights it equals frame i−1's colour up to the float rounding of the rebuilt ray)."""
    from dbench.datasets.sequence.reshade import select_strata

    k = S.FLICKER_SWITCH
    for i in (1, 5, k - 1, k + 1):  # lights unchanged
        g, prev = flicker[i].gradient, flicker[i - 1]
        chosen = np.isfinite(g[..., 0])
        np.testing.assert_array_equal(chosen, select_strata(prev.color, prev.depth))
        np.testing.assert_allclose(g[chosen], prev.color[chosen], rtol=1e-4, atol=1e-6)
        lum = prev.color @ np.array([0.2126, 0.7152, 0.0722])
        for y, x in zip(*np.nonzero(chosen)):  # the brightest hit pixel of its stratum
            y0, x0 = y // 3 * 3, x // 3 * 3
            block = np.where(prev.depth[y0:y0 + 3, x0:x0 + 3, 0] > 0,
                             lum[y0:y0 + 3, x0:x0 + 3], -np.inf)
            assert lum[y, x] == block.max()
    chosen = np.isfinite(flicker[k].gradient[..., 0])
    assert not np.allclose(flicker[k].gradient[chosen], flicker[k - 1].color[chosen])


def test_reshaded_passes_start_from_their_own_hits_above_1_spp(renderer, seq_cache):
    """Above 1 spp each pass of a selected pixel is re-shaded from that pass's own hit of frame
    i−1 (docs/temporal.md §2): on a static camera with unchanged lights the gradient buffer is
    the previous frame's colour (the mean of the same passes). Aimed at the pixel's mean
    position instead, 2.5 % of the strata had G > 0.01 (flicker, 64², 4 spp)."""
    seq = datasets.load("flicker", spp=3, res=RES, frames=3, ref_spp=16, cache=seq_cache,
                        progress=False)
    for i in (1, 2):
        g, prev = seq[i].gradient, seq[i - 1].color
        chosen = np.isfinite(g[..., 0])
        assert chosen.sum() > 20
        np.testing.assert_allclose(g[chosen], prev[chosen], rtol=1e-4, atol=1e-5)


def test_select_strata_takes_one_brightest_hit_per_stratum():
    from dbench.datasets.sequence.reshade import select_strata

    color = np.zeros((4, 5, 3))
    color[0, 1] = 2.0
    color[1, 2] = 3.0          # brighter, but no hit
    color[3, 4] = 1.0          # a partial stratum at the corner
    depth = np.ones((4, 5))
    depth[1, 2] = 0.0
    sel = select_strata(color, depth)
    assert sel[0, 1] and not sel[1, 2] and sel[3, 4]
    assert sel.sum() == 4      # 2 × 2 strata, each with hit pixels
    assert not select_strata(color, np.zeros((4, 5))).any()


def test_gradient_frame_emulation_reuses_the_previous_random_numbers(renderer, seq_cache):
    """The older emulation (``gradient="frame"``, spec §6.4): bit-identical to frame i−1 while
    the lights do not change."""
    from dbench.datasets.sequence.load import load_sequence

    seq = load_sequence("flicker", spp=1, res=RES, frames=3, cache=seq_cache, progress=False,
                        needs={"color", "gradient"}, gradient="frame")
    for i in (1, 2):
        np.testing.assert_array_equal(seq[i].gradient, seq[i - 1].color)


def test_cache_is_reused(renderer, seq_cache, flicker):
    again = datasets.load("flicker", spp=1, res=RES, frames=18, ref_spp=16, cache=seq_cache,
                          progress=False)
    assert again.meta["rendered"] == [] and len(again.meta["cache_hits"]) > 0
    np.testing.assert_array_equal(again[7].color, flicker[7].color)
    prefix = datasets.load("flicker", spp=1, res=RES, frames=3, ref_spp=16, cache=seq_cache,
                           progress=False, needs={"color"})
    assert prefix.meta["rendered"] == [] and not prefix.has("albedo")


# -- the sequence runner -----------------------------------------------------------------------------

def test_run_sequence_and_temporal_stability():
    seq = synthetic.synthetic_sequence(12, 16, frames=10)
    r = BS.run_sequence("accumulate", seq, warmup=3, keep_outputs=True)
    assert len(r.per_frame) == 10 and {"rmse", "ssim", "time_s"} <= set(r.per_frame[0])
    assert r.summary["mean_rmse"] == pytest.approx(np.mean(r.series("rmse")[3:]))
    refs = [f.reference for f in seq]
    perfect = BS.temporal_stability(refs, refs, warmup=3)
    assert perfect["t_rmse"] == 0 and perfect["tpsnr"] == 100.0
    noisy = BS.temporal_stability([f.color for f in seq], refs, warmup=3)
    assert noisy["t_rmse"] > r.summary["t_rmse"] > 0
    with pytest.raises(DbenchInputError, match="cannot run"):
        BS.run_sequence("bmfr", Sequence([Frame(color=np.ones((4, 4, 3)))]))


def test_plots_and_strip(tmp_path):
    seq = synthetic.synthetic_sequence(12, 16, frames=9)
    res = BS.compare(seq, ["noisy", "accumulate"], warmup=2)
    p1 = sequence_figures.plot_errors(res, tmp_path / "err.png", events={"change": 4})
    p2 = sequence_figures.strip(seq, res, tmp_path / "strip.png", frames=[0, 4, 8])
    assert p1.stat().st_size > 0 and p2.stat().st_size > 0


def test_speed_benchmark_runs_small():
    out = speed_sequence.benchmark(24, 32, repeats=2, method_names=("accumulate", "bmfr"))
    assert set(out["methods"]) == {"accumulate", "bmfr"}
    assert all(v["median_ms"] > 0 for v in out["methods"].values())


# -- quality on rendered sequences -------------------------------------------------------------------

def _quality(scene, res, frames, cache):
    from dbench import registry
    methods = ("noisy", "accumulate", "svgf", "asvgf", "bmfr")
    # the buffers these methods read and the reference: the same pixels as a load of every
    # buffer (emitter, emission and statistics are renders of their own), fewer renders
    needs = set().union(*(registry.get(n).needs for n in methods)) | {"reference"}
    seq = datasets.load(scene, spp=1, res=res, frames=frames, ref_spp=256, cache=cache,
                        needs=needs, progress=False)
    # BS.compare without ColorVideoVDP (seconds per method): the checks read the RMSE only,
    # and the video metric has its own tests (tests/metrics/test_video_quality.py)
    res_ = {n: BS.run_sequence(registry.get(n), seq, keep_outputs=False, cvvdp=False)
            for n in methods}
    return res_, {n: r.summary["mean_rmse"] for n, r in res_.items()}


def _check_flicker(res, mean, with_bmfr=False):
    k = S.FLICKER_SWITCH
    for n in ("svgf", "asvgf", "bmfr"):
        assert mean[n] < mean["noisy"], n
    for n in ("svgf", "asvgf") + (("bmfr",) if with_bmfr else ()):
        assert mean[n] < mean["accumulate"], n
    assert BS.window_mean(res["asvgf"], "rmse", k, 5) < BS.window_mean(res["svgf"], "rmse", k, 5)


def test_quality_small(renderer, seq_cache):
    """32×32, 1 spp, reference 256 spp, mean after 8 warm-up frames (results/temporal.md has
    the same at 64-256 px). Orbit: every method beats noisy; at this size plain accumulation
    beats the spatial filters on a static-light scene (see results/temporal.md), so that
    comparison is only made on flicker, where svgf and asvgf must also beat accumulate and
    asvgf must beat svgf over the 5 frames after the light change."""
    res, mean = _quality("flicker", 32, S.FLICKER_SWITCH + 6, seq_cache)
    _check_flicker(res, mean)
    _, mean = _quality("orbit", 32, 16, seq_cache)
    for n in ("accumulate", "svgf", "asvgf", "bmfr"):
        assert mean[n] < mean["noisy"], n


@pytest.mark.slow
def test_quality_128(renderer, seq_cache):
    """The flicker check at 128×128 and 24 frames (about 2.5 minutes of rendering on 2 cores;
    orbit is checked at 32 px above, and at 128 px in the published sequence sweep)."""
    res, mean = _quality("flicker", 128, 24, seq_cache)
    _check_flicker(res, mean)


def test_steady_methods_run_on_sequences_frame_by_frame():
    from dbench import registry
    from dbench.run.sequence_run import run_sequence
    from dbench.synthetic import synthetic_sequence
    from dbench.registry import Denoiser

    class Counting(Denoiser):
        name = "counting"
        kinds = {"steady"}
        needs = {"color"}
        defaults = {}

        def __init__(self):
            super().__init__()
            self.since_reset = 0
            self.seen = []

        def reset(self):
            self.since_reset = 0

        def denoise(self, data):
            self.since_reset += 1
            self.seen.append(self.since_reset)
            return data.color.copy()

    seq = synthetic_sequence(12, 16, frames=6)
    m = Counting()
    assert m.applies_to("sequence", {"color"}) == (True, "")
    assert m.per_frame("sequence") and not m.per_frame("steady")
    run_sequence(m, seq, warmup=2)
    assert m.seen == [1] * 8  # reset before every frame (and the untimed rerun of frames 0-1)
    jbf = registry.get("jbf")
    ok, why = jbf.applies_to("sequence", {"color", "albedo", "normal", "depth"})
    assert ok, why
    assert not registry.get("statistical").applies_to("sequence", {"color", "albedo", "normal",
                                                                  "depth"})[0]
    assert not registry.get("svgf").per_frame("sequence")


def test_sequence_frames_carry_the_statistics_of_their_own_samples(renderer, tmp_cache):
    """Per-frame sample statistics (issue: every method on every kind): the colour is the
    mean of 1-spp passes whether or not statistics are asked for, a 1-spp frame is one render
    with the frame's seed, and single-frame statistical methods run on the frames."""
    from dbench import datasets, registry
    from dbench.run.harness import run_sequence_cell
    from dbench.datasets.sequence import load as S
    from dbench.datasets.mitsuba_env import mitsuba

    with_stats = datasets.load("orbit", spp=4, res=16, frames=3, cache=tmp_cache,
                               needs={"color", "stats", "albedo", "normal", "reference"},
                               ref_spp=32, progress=False)
    plain = S.load_sequence("orbit", spp=4, res=16, frames=3, needs={"color"},
                            cache=datasets.Cache(tmp_cache.root / "other"), progress=False)
    for a, b in zip(with_stats, plain):
        np.testing.assert_array_equal(a.color, b.color)
        np.testing.assert_array_equal(a.stats.n, 4)
    # a frame's entry holds its noisy colour uncompressed beside the ZIP G-buffer, with
    # statistics or without (S.RAW_IMAGES), and reads back the same
    import OpenEXR
    for root in (tmp_cache.root, tmp_cache.root / "other"):
        files = sorted(root.glob("seq-frame/*/buffers.exr"))
        assert len(files) == 3
        for f in files:
            with OpenEXR.File(str(f)) as exr:
                parts = {p.header["compression"]: sorted(p.channels) for p in exr.parts}
            assert parts.pop(OpenEXR.NO_COMPRESSION) == ["color"]
            assert list(parts) == [OpenEXR.ZIP_COMPRESSION] and "albedo" in parts.popitem()[1]
    again = S.load_sequence("orbit", spp=4, res=16, frames=3, needs={"color", "albedo"},
                            cache=tmp_cache, progress=False)
    assert not any(r.startswith("frame") for r in again.meta["rendered"])
    for a, b in zip(again, with_stats):
        np.testing.assert_array_equal(a.color, b.color)
        np.testing.assert_array_equal(a.albedo, b.albedo)
    mi = mitsuba()
    sc = datasets.get_scene("orbit")
    d = sc.frame_dict(mi, 16, 2, 2)
    integ = mi.load_dict(S._matched_integrator(d["integrator"]), optimize=False)
    one = S._render_dict(d, 1, S.frame_seed(0, 2), integrator=integ)[..., :3]
    np.testing.assert_array_equal(S.render_frame(sc, 16, 1, 0, 2, 2, 2)["color"], one)
    result = run_sequence_cell(registry.get("statistical"), [with_stats], warmup=1)
    assert not result.skipped and np.isfinite(result.metrics["rmse"])


def test_temporal_study_tables_give_intervals_and_flag_variants_not_below_accumulate():
    from dbench.studies.temporal_study import VARIANTS, _interval, tables

    rows = []
    for seed, (acc, good, bad) in enumerate([(1.0, 0.8, 1.2), (1.2, 0.9, 1.3), (1.1, 0.85, 1.1)]):
        for label, v in (("accumulate", acc), ("svgf", good), ("bmfr", bad)):
            rows.append({"scene": "orbit", "label": label, "seed": seed, "rmse": v,
                         "relmse": v, "t_rmse": v})
    text = tables(rows, 64)
    assert "| svgf | 0.8500 ± 0.1242 | 0.773 |" in text
    assert "| bmfr | 1.2000 ± 0.2484 | 1.091 (not below) |" in text
    # paired over the seeds: svgf's interval overlaps accumulate's (1.1 ± 0.25), but seed by
    # seed it is below every time (−0.2, −0.3, −0.25); bmfr's differences straddle 0
    assert "| — | -0.2500 ± 0.1242 (below) |" in text
    assert "| — | +0.1000 ± 0.2484 (tied) |" in text
    assert _interval([2.0]) == (2.0, 0.0)
    assert len({label for label, _, _ in VARIANTS}) == len(VARIANTS)


def test_development_study_table_gives_geometric_mean_ratios_to_accumulate():
    """dbench.studies.temporal_dev: ratios to accumulate on the same scene and seed, geometric
    mean over the pairs, and the share of pairs where relMSE is below accumulate's."""
    from dbench.studies.temporal_dev import VARIANTS, table

    rows = []
    for scene, seed, acc, svgf in (("a", 0, 1.0, 0.5), ("a", 1, 2.0, 4.0), ("b", 0, 1.0, 0.5),
                                   ("b", 1, 1.0, 2.0)):
        for label, v in (("accumulate", acc), ("svgf", svgf)):
            rows.append({"scene": scene, "seed": seed, "label": label, "rmse": v,
                         "rmse_surface": v, "relmse": v})
    text = table(rows)
    assert "| svgf | 1.000 | 1.000 | 1.000 | 50% |" in text   # (0.5 · 2 · 0.5 · 2)^¼ = 1
    assert "4 pairs" in text and "2 seeds each" in text
    assert len({label for label, _, _ in VARIANTS}) == len(VARIANTS)
    assert sum("(default)" in label for label, _, _ in VARIANTS) == 6


def test_gradient_samples_cost_counts_with_the_methods_that_use_them(flicker):
    """docs/temporal.md §2: the per-frame seconds of the re-shaded samples (cached or not) are in
    the sequence's meta, and the tables add them to the total time of a cell that used them."""
    from dbench.report.tables import cells_frame

    assert flicker.meta["gradient_per_frame_s"] > 0
    base = {"status": "ok", "scene": "flicker", "spp": 1, "res": 32, "rmse": 0.1,
            "time_s": 0.01, "render_s": 0.2}
    df = cells_frame([{**base, "method": "svgf"},
                      {**base, "method": "asvgf", "gradient_s": 0.05}]).set_index("method")
    assert df.loc["asvgf", "gradient_s"] == 0.05 and df.loc["svgf", "gradient_s"] == 0
    assert df.loc["asvgf", "total_s"] - df.loc["svgf", "total_s"] == pytest.approx(0.05)


def test_temporal_targets_pair_seeds_and_tell_a_three_seed_tie_from_a_real_one():
    """dbench.studies.temporal_targets: filter − accumulate seed by seed, over the first 3 seeds
    and over all; a small steady gain is tied over 3 seeds and below over 10."""
    from dbench.studies.temporal_targets import FILTERS, SETTINGS, paired, tables, verdict

    rng = np.random.default_rng(0)
    rows = []
    for seed in range(10):
        acc = 1.0 + 0.2 * rng.standard_normal()
        values = {"noisy": acc + 5.0, "accumulate": acc, "svgf": acc - 0.01,
                  "asvgf": acc - 0.05, "bmfr": acc + 0.05}
        # svgf: −0.01 ± 0.02 per seed, too little to show over 3 seeds
        values["svgf"] += 0.02 * (1 if seed % 2 else -1) * (1 if seed < 3 else 0.1)
        for scene in ("orbit", "flicker"):
            for name, v in values.items():
                rows.append({"setting": "64", "scene": scene, "method": name, "seed": seed,
                             "rmse_surface": v, "relmse": v, "t_rmse": v,
                             **({"rmse_after_change": v} if scene == "flicker" else {})})
    three = paired([r for r in rows if r["method"] == "svgf" and r["scene"] == "orbit"],
                   [r for r in rows if r["method"] == "accumulate" and r["scene"] == "orbit"],
                   "relmse", 3)
    assert three[2] == 3 and "(tied)" in verdict(three)
    text = tables(rows)
    line = next(x for x in text.splitlines() if x.startswith("| orbit | svgf |"))
    assert line.count("(tied)") == 2 and line.count("(below)") == 2, line
    assert line.endswith("| below / below |")
    assert "| orbit | bmfr | +0.05" in text and "(above)" in text
    # asvgf − svgf = −0.04 − svgf's perturbation, whose mean over the 10 seeds is −0.0018
    switch = paired([r for r in rows if r["method"] == "asvgf" and r["scene"] == "flicker"],
                    [r for r in rows if r["method"] == "svgf" and r["scene"] == "flicker"],
                    "rmse_after_change")
    assert switch[0] == pytest.approx(-0.0382) and switch[2] == 10
    assert f"light switch (RMSE), 10 seeds: {verdict(switch)}" in text
    assert "(below)" in verdict(switch) and "`t_rmse` on `orbit`, 10 seeds: -0.03" in text
    assert paired(rows[:1], rows[:1], "relmse") is None  # one seed: no interval
    assert set(FILTERS) == {"svgf", "asvgf", "bmfr"} and set(SETTINGS) == {"64", "128", "128x76"}


@pytest.mark.parametrize("args", [["--settings", "256"], ["--seeds", "2"]])
def test_temporal_targets_refuse_bad_arguments_in_one_line(args, capsys):
    from dbench.studies.temporal_targets import main

    with pytest.raises(SystemExit) as exc:
        main(args + ["--out", "unused"])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert ("--settings" in err and "64, 128, 128x76" in err) or "--seeds" in err
