"""Temporal antialiasing after the temporal denoisers (dbench/methods/temporal/taa.py;
docs/methods/bmfr.md §1 step 6 and §6 ``taa``)."""
import numpy as np
import pytest

from dbench.methods.temporal.taa import (TAA_ALPHA, from_ycocg, taa_fast, taa_reference,
                                         to_ycocg)


def _case(h=23, w=31, seed=0):
    rng = np.random.default_rng(seed)
    cur = rng.gamma(1.0, 1.0, (h, w, 3)).astype(np.float32)
    hist = rng.gamma(1.0, 2.0, (h, w, 3)).astype(np.float32)
    motion = rng.uniform(-2.5, 2.5, (2, h, w)).astype(np.float32)
    return cur, hist, motion


def test_ycocg_round_trip():
    rgb = np.random.default_rng(1).normal(size=(50, 3))
    np.testing.assert_allclose(from_ycocg(to_ycocg(rgb)), rgb, atol=1e-12)
    np.testing.assert_allclose(to_ycocg(np.array([1.0, 1.0, 1.0])), [1.0, 0.0, 0.0])


def test_fast_equals_reference_with_edges_and_missing_values():
    """The compiled pass equals the readable one within float32 rounding, with motion that is
    NaN, leaves the image (floor(q) < −1 or ≥ W), lands on its border (−1 < q < 0: only the taps
    inside count) and a non-finite current pixel (kept as it is)."""
    cur, hist, motion = _case()
    motion[:, 0, 0] = np.nan
    motion[:, 5, 5] = (-40.0, 3.0)
    motion[:, 6, 6] = (-6.5, -6.5)    # q = (-0.5, -0.5): one tap inside
    motion[:, 7, 30] = (0.5, 0.0)     # q.x = 30.5: the right column's taps only
    motion[:, 8, 8] = (-9.0, 0.0)     # q.x = -1 exactly: the tap at x = 0 has weight 0
    cur[3, 3] = np.nan
    for alpha in (TAA_ALPHA, 0.5):
        ref = taa_reference(cur, hist, motion, alpha)
        fast = taa_fast(cur, hist, motion, alpha)
        assert fast.dtype == np.float32 and fast.shape == cur.shape
        np.testing.assert_array_equal(np.isnan(fast), np.isnan(ref))
        np.testing.assert_allclose(fast, ref, rtol=1e-6, atol=1e-6)
        for out in (ref, fast):
            assert np.isnan(out[3, 3]).all()
            np.testing.assert_array_equal(out[0, 0], cur[0, 0])
            np.testing.assert_array_equal(out[5, 5], cur[5, 5])
        assert (ref != cur).mean() > 0.8  # the history counts nearly everywhere


def test_without_history_or_with_alpha_one_the_output_is_the_input():
    cur, hist, motion = _case()
    for fn in (taa_reference, taa_fast):
        np.testing.assert_array_equal(fn(cur, None, motion), cur)
        np.testing.assert_array_equal(fn(cur, hist, None), cur)
        np.testing.assert_allclose(fn(cur, hist, motion, 1.0), cur)
    with pytest.raises(ValueError, match="alpha"):
        taa_fast(cur, hist, motion, 0.0)
    with pytest.raises(Exception, match="motion"):
        taa_fast(cur, hist, motion[:, :5])


def test_a_static_sequence_averages_the_noise_and_a_change_does_not_ghost():
    """Static camera (zero motion): over noisy frames of a flat grey image TAA is a running
    mean of weight α = 0.2 clamped to each 3×3 neighbourhood's range, so the frame-to-frame
    noise falls well below the input's; when the image turns black the clamp to the new
    neighbourhood drops the old grey at once (no ghost)."""
    h = w = 32
    rng = np.random.default_rng(3)
    motion = np.zeros((2, h, w), np.float32)
    hist = None
    outs = []
    for _ in range(30):
        frame = (0.5 + 0.1 * rng.standard_normal((h, w, 3))).astype(np.float32)
        hist = taa_fast(frame, hist, motion)
        outs.append(hist)
    assert np.std(outs[-1]) < 0.5 * 0.1
    assert abs(float(np.mean(outs[-1])) - 0.5) < 0.01
    black = np.zeros((h, w, 3), np.float32)
    np.testing.assert_array_equal(taa_fast(black, hist, motion), black)
    np.testing.assert_array_equal(taa_reference(black, hist, motion), black)


def test_the_history_follows_the_motion_vectors():
    """A bright column that moves one pixel right per frame: with the motion vectors pointing
    one pixel left (to where each pixel was) the history is fetched from the column's previous
    place, so the output keeps the column at full brightness instead of smearing it."""
    h, w = 8, 16
    motion = np.zeros((2, h, w), np.float32)
    motion[0] = -1.0
    hist = None
    for t in range(6):
        frame = np.full((h, w, 3), 0.1, np.float32)
        frame[:, 4 + t] = 1.0
        hist = taa_fast(frame, hist, motion)
    np.testing.assert_allclose(hist[:, 9], 1.0, atol=1e-6)
    assert hist[:, 8].max() <= 0.1 + 1e-6


@pytest.mark.parametrize("name", ["bmfr", "svgf", "asvgf", "accumulate"])
def test_methods_run_taa_as_an_option(name):
    """``taa=True`` on the temporal methods: frame 0 equals the method without it (no history),
    later frames differ, ``reset`` restarts it, and bad values are refused with their name."""
    from dbench import registry
    from dbench.synthetic import synthetic_sequence
    from dbench.errors import DbenchInputError

    seq = synthetic_sequence(24, 32, frames=3, shift=1, seed=0)
    plain, with_taa = registry.get(name), registry.get(name, taa=True)
    first = [m.denoise(seq.frames[0]) for m in (plain, with_taa)]
    np.testing.assert_array_equal(first[0], first[1])
    second = [m.denoise(seq.frames[1]) for m in (plain, with_taa)]
    assert np.isfinite(second[1]).all() and not np.array_equal(second[0], second[1])
    with_taa.reset()
    plain.reset()
    np.testing.assert_array_equal(with_taa.denoise(seq.frames[0]), plain.denoise(seq.frames[0]))
    for bad in ({"taa": 1}, {"taa": True, "taa_alpha": 0.0}, {"taa_alpha": 1.5}):
        with pytest.raises(DbenchInputError, match="taa"):
            registry.get(name, **bad)


def test_a_missing_pixels_history_never_spreads():
    """A non-finite previous output (a missing pixel with no history) is no tap of the bilinear
    fetch: pixels whose own input is finite stay finite, in both forms."""
    rng = np.random.default_rng(4)
    h, w = 6, 7
    cur = rng.random((h, w, 3)).astype(np.float32)
    hist = rng.random((h, w, 3)).astype(np.float32)
    hist[2, 3] = np.nan
    motion = np.full((2, h, w), 0.5, np.float32)  # every fetch straddles four pixels
    for fn in (taa_reference, taa_fast):
        out = fn(cur, hist, motion, 0.2)
        assert np.isfinite(out).all(), fn.__name__
    np.testing.assert_allclose(taa_fast(cur, hist, motion, 0.2),
                               taa_reference(cur, hist, motion, 0.2), rtol=1e-5, atol=1e-6)
