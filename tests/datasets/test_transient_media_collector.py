"""Collector (b) for participating media (``transient_prbvolpath_stats``) against collector (a):
bit-identical statistics, state independent of spp, no overflow with the default slots, the
overflow guard, and the loader's choice (docs/methods/statistical.md §11.1-11.2, docs/transient.md §5)."""
from __future__ import annotations

import numpy as np
import pytest
# (pytest puts tests/ on sys.path)
from test_transient import (  # noqa: E402
    _assert_same, assert_colour_alone_is_the_same, assert_rows_found, state_bytes)

RES, BINS, SPP = 8, 20, 4


@pytest.fixture(scope="module")
def fog(tr):
    from dbench.datasets.scenes import catalogue as scenes
    sc = scenes.get("fog-transient")
    assert sc.integrator == "transient_prbvolpath"
    return sc


@pytest.mark.parametrize("transform", ["identity", "box-cox"])
def test_media_collector_equals_passes_bit_for_bit(tr, fog, transform):
    """Same seeds, 1-spp passes, one camera per call: the slots inside transient_prbvolpath give
    the float64 power sums, non_zero counts, colour and moments of the film histogram, bit for
    bit (medium scatter events do next-event estimation too)."""
    a = tr.collect_passes(fog, RES, SPP, seed=2, bins=BINS, stats=(transform, 0.5), copies=1)
    b = tr.collect_in_integrator(fog, RES, SPP, seed=2, bins=BINS, transform=transform,
                                 lam=0.5, per_pass=True)
    assert b.non_zero.max() > 0 and (b.non_zero > 0).mean() > 0.2   # the test sees data
    _assert_same(a, b)
    assert_rows_found(b)
    assert_colour_alone_is_the_same(tr, fog, b, RES, BINS, SPP, transform)
    assert b.timing["collector"] == "b" and b.timing["slots"] == 2 * fog.max_depth
    assert b.timing["n_overflow"] == 0 and b.timing["n_nonfinite"] == 0


def test_media_state_independent_of_spp(tr, fog):
    """All spp in one call: the statistics state is (H·W·T·3) × 3 float64 sums + (H·W·T) packed
    uint64 counts + 4 uint32 counters, whatever the spp; 0 ≤ non_zero ≤ spp."""
    sizes = {}
    for spp in (1, 4, 32):
        out = tr.collect_in_integrator(fog, RES, spp, seed=1, bins=BINS)
        sizes[spp] = out.timing["state_bytes"]
        assert out.non_zero.min() >= 0 and out.non_zero.max() <= spp
        # identity: S1 / n is the colour, S2 ≥ S1² / n
        np.testing.assert_allclose(out.sums["s1"] / spp, out.color, rtol=1e-6, atol=1e-9)
        assert np.all(out.sums["s2"] * spp >= out.sums["s1"] ** 2 * (1 - 1e-9) - 1e-12)
    voxels = RES * RES * BINS * 3
    state = state_bytes(voxels) + 4 * 4 + 2 * RES * RES * 3 * 8
    assert sizes[1] == sizes[4] == sizes[32] == state


def test_media_default_slots_never_overflow(tr, fog):
    """2·max_depth slots hold every contribution of a fog path (emitter hits at depth
    0…max_depth, next-event estimates at vertices 1…max_depth − 1); fewer slots force slots out
    early and count it."""
    out = tr.collect_in_integrator(fog, RES, 64, seed=3, bins=BINS)
    assert out.timing["n_overflow"] == 0 and out.timing["slots"] == 16
    assert out.non_zero.max() <= 64 and out.timing["n_reentry"] > 0
    few = tr.collect_in_integrator(fog, RES, 64, seed=3, bins=BINS, slots=2)
    assert few.timing["n_overflow"] > 0
    # the same contributions are summed (float32 sums in another grouping)
    np.testing.assert_allclose(few.sums["s1"], out.sums["s1"], rtol=1e-4, atol=1e-6)


def _null_emitters(mi, res):
    """Two emitting null-BSDF rectangles in front of an emitting diffuse one: a camera ray picks
    up three emitter hits before its first real vertex, more than 2·max_depth = 2 slots."""
    from dbench.datasets.scenes.parts import camera_dict, diffuse_bsdf, rect_shape
    T = mi.ScalarTransform4f
    d = {"type": "scene",
         "sensor": camera_dict(mi, res, origin=[0, 0, 3], target=[0, 0, 0], fov=20)}
    for i, (z, value) in enumerate(((1.0, 1.0), (0.0, 2.0), (-1.0, 3.0))):
        bsdf = diffuse_bsdf((0.5, 0.5, 0.5)) if i == 2 else {"type": "null"}
        d[f"plane{i}"] = rect_shape(mi, T().translate([0, 0, z]).scale(2.0), bsdf,
                               {"type": "area", "radiance": {"type": "rgb", "value": [value] * 3}})
    return d


def test_media_overflow_guard_counts_and_keeps_energy(tr):
    """Emitters on null-BSDF shapes break the 2·max_depth bound: the extra contribution is
    flushed on its own and counted (n_overflow > 0), never lost. Here its bin differs from the
    others', so the statistics still equal collector (a)'s."""
    sc = tr.TransientScene(name="test-null-emitters", kind="transient", description="test",
                           build=_null_emitters, max_depth=1, window_start=1.5,
                           window_end=4.5, default_bins=6,
                           integrator="transient_prbvolpath", steady_integrator="volpath")
    a = tr.collect_passes(sc, 4, 2, seed=0, stats=("identity", 0.5), copies=1)
    b = tr.collect_in_integrator(sc, 4, 2, seed=0, per_pass=True)
    assert b.timing["slots"] == 2 and b.timing["n_overflow"] == 4 * 4 * 2
    _assert_same(a, b)


def test_loader_picks_collector_b_for_media_and_keys_the_cache(tr, tmp_cache):
    """``collector='auto'`` resolves to (b) on fog-transient; (a) and (b) are separate cache
    entries (different paths), each found again on a second load."""
    from dbench import datasets
    kw = dict(spp=SPP, res=RES, bins=BINS, needs={"color", "stats"}, cache=tmp_cache,
              progress=False)
    b = datasets.load("fog-transient", **kw)
    assert b.meta["collector"] == "b" and b.meta["stats_diagnostics"]["n_overflow"] == 0
    a = datasets.load("fog-transient", collector="a", **kw)
    assert a.meta["collector"] == "a" and "color" in a.meta["rendered"]
    assert not np.array_equal(a.color, b.color)
    again = datasets.load("fog-transient", **kw)
    assert {"color", "stats"} <= set(again.meta["cache_hits"]) and not again.meta["rendered"]
    np.testing.assert_array_equal(again.stats.var_mean, b.stats.var_mean)


@pytest.mark.parametrize("name", ["cloud-transient", "fog-unwarped"])
def test_media_collector_exact_with_null_collisions_and_unwarping(tr, name):
    """The heterogeneous cloud (null collisions, ratio-tracked next-event estimation) and the
    unwarped fog (OPL starting below 0) take the other branches of the integrator: still
    bit-identical to collector (a)."""
    from dbench.datasets.scenes import catalogue as scenes
    if name not in scenes.available():
        pytest.skip(f"{name} is not in this catalogue")
    sc = scenes.get(name)
    a = tr.collect_passes(sc, RES, SPP, seed=2, bins=BINS, stats=("identity", 0.5), copies=1)
    b = tr.collect_in_integrator(sc, RES, SPP, seed=2, bins=BINS, per_pass=True)
    assert (b.non_zero > 0).mean() > 0.1 and b.timing["n_overflow"] == 0
    _assert_same(a, b)


def test_collector_b_refuses_scenes_made_from_whole_passes(tr, fog):
    """A step emission (cumsum of each pass) cannot be summed inside one render."""
    import dataclasses
    from dbench.errors import DbenchInputError
    if not hasattr(fog, "needs_passes"):
        pytest.skip("no step emission in this catalogue")
    step = dataclasses.replace(fog, name="fog-step-test", emission="step")
    assert step.needs_passes
    with pytest.raises(DbenchInputError, match="whole passes"):
        tr.collect_in_integrator(step, RES, SPP, bins=BINS)
