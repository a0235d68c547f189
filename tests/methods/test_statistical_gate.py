"""Tests of ``statistical-gate``: the Welch-test denoiser followed by ProDen's t-test gate
(spec/statistical.md §12, check 17)."""
from __future__ import annotations

import numpy as np
import pytest

from dbench.data import Frame, SampleStats
from dbench.errors import DbenchInputError
from dbench.methods.statistical import core as sc
from dbench.methods.statistical import linear_variance
from dbench.registry import get

from test_statistical import synthetic_case  # pytest puts this folder on sys.path


def _frame(seed=0, h=14, w=15):
    color, stats, albedo, normal, depth = synthetic_case(h, w, seed=seed)
    return Frame(color=color.astype(np.float32), albedo=albedo.astype(np.float32),
                 normal=normal.astype(np.float32), depth=depth.astype(np.float32), stats=stats)


def test_defaults_are_statistical_with_the_gate_on():
    gated, plain = get("statistical-gate"), get("statistical")
    assert gated.params["gate"] is True and plain.params["gate"] is False
    assert {k: v for k, v in gated.params.items() if k != "gate"} == \
        {k: v for k, v in plain.params.items() if k != "gate"}
    assert gated.kinds == {"steady"} and gated.needs == plain.needs


def test_equals_plain_filter_then_gate():
    """Known composition: output = proden_gate(noisy, statistical output, Var(linear mean))."""
    frame = _frame(seed=3)
    den = get("statistical", radius=3, backend="numba").denoise(frame)
    out = get("statistical-gate", radius=3, backend="numba").denoise(frame)
    var = linear_variance(frame.stats, frame.color)
    expected = sc.proden_gate(frame.color.astype(np.float64), den.astype(np.float64), var)
    np.testing.assert_allclose(out, expected, rtol=1e-6, atol=1e-7)


def test_gate_factor_known_values():
    np.testing.assert_allclose(sc.proden_gate_factor([4.2, 3.2, 5.2]),
                               [0.5, 0.97725, 0.02275], atol=1e-5)


def test_consistent_as_variance_vanishes():
    """With zero variance everywhere the gate returns the noisy input exactly wherever the
    filter changed it (t = ∞), and the filtered value where it did not (d = 0)."""
    rng = np.random.default_rng(5)
    h, w = 10, 11
    color = rng.random((h, w, 3)) + 0.5
    stats = SampleStats(n=np.full((h, w, 3), 64.0), mean=color, var_mean=np.zeros((h, w, 3)),
                        m3=np.zeros((h, w, 3)), transform="identity")
    frame = Frame(color=color.astype(np.float32), albedo=np.full((h, w, 3), 0.5, np.float32),
                  normal=np.tile(np.float32([0, 0, 1]), (h, w, 1)),
                  depth=np.ones((h, w, 1), np.float32), stats=stats)
    out = get("statistical-gate", radius=2).denoise(frame)
    np.testing.assert_allclose(out, frame.color, rtol=0, atol=1e-6)


def test_never_further_from_noisy_than_plain():
    """The gate only mixes towards the noisy value: |gated − noisy| <= |plain − noisy|."""
    frame = _frame(seed=8)
    plain = get("statistical", radius=4).denoise(frame).astype(np.float64)
    gated = get("statistical-gate", radius=4).denoise(frame).astype(np.float64)
    noisy = frame.color.astype(np.float64)
    assert np.all(np.abs(gated - noisy) <= np.abs(plain - noisy) + 1e-6)


def test_nonfinite_pixels_do_not_spread():
    frame = _frame(seed=9)
    color = frame.color.copy()
    color[4, 5] = np.nan
    mean = np.array(frame.stats.mean, copy=True)
    mean[4, 5] = np.nan
    st = frame.stats
    bad = frame.with_buffers(color=color, stats=SampleStats(n=st.n, mean=mean,
                                                            var_mean=st.var_mean, m3=st.m3,
                                                            transform=st.transform))
    out = get("statistical-gate", radius=3).denoise(bad)
    finite = np.isfinite(out).all(-1)
    finite[4, 5] = True
    assert finite.all()


def test_bad_input_and_transient_data_rejected():
    frame = _frame(seed=1)
    with pytest.raises(DbenchInputError, match="stats"):
        get("statistical-gate").denoise(frame.with_buffers(stats=None))
    with pytest.raises(DbenchInputError, match="gate_alpha"):
        get("statistical-gate", gate_alpha=1.5)
    assert not get("statistical-gate").applies_to("transient", {"color", "albedo", "normal",
                                                               "depth", "stats"})[0]
