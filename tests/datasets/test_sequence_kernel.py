"""Sequence frames summed on the device (dbench/datasets/sequence/frames.py with
render_moments.pass_sums; README.md, "How renders work") against the readable reference, the
same 1-spp passes filmed by ``mi.render`` and summed on the host: the same samples, so the
colour and every G-buffer channel are equal bit for bit; the colour statistics agree within
the float64 rounding of the two transforms (tests/datasets/test_render_moments.py: RTOL, ULPS)."""
import numpy as np
import pytest

from dbench import datasets
from dbench.datasets import render_moments
from dbench.datasets.sequence import load as S
from dbench.datasets.sequence import frames as F

pytestmark = pytest.mark.mitsuba


@pytest.fixture(scope="module")
def jit(renderer):
    if not render_moments.jit_variant(renderer.variant()):
        pytest.skip("the one-pass kernel needs a JIT variant")
    return renderer


@pytest.mark.parametrize("scene,gbuffer,spp", [("mirror-pan", "psr", 3),
                                                ("mirror-pan", "psr-glossy", 2),
                                                ("orbit", "matched", 3),
                                                ("flicker", "psr", 1)])
def test_device_sums_equal_the_filmed_passes(jit, scene, gbuffer, spp):
    sc = datasets.get_scene(scene)
    stats = ("box-cox", 0.5)
    # camera of frame 1, lights of 2, seeds of 1: the gradient frame's combination too
    got = F.render_frame(sc, 16, spp, 5, 1, 2, 1, stats=stats, gbuffer=gbuffer, kernel=True)
    want = F.render_frame(sc, 16, spp, 5, 1, 2, 1, stats=stats, gbuffer=gbuffer, kernel=False)
    st, ref = got.pop("stats"), want.pop("stats")
    assert got.keys() == want.keys() and {"color", "albedo", "position"} <= set(got)
    for k in got:
        np.testing.assert_array_equal(got[k], want[k], err_msg=k)
    np.testing.assert_array_equal(st.n, spp)
    # S1, S2, S3 of u = g(x) − g(0), the kernel's x^λ/λ against the host's difference
    np.testing.assert_allclose(st.mean, ref.mean, rtol=1e-9)
    np.testing.assert_allclose(st.var_mean, ref.var_mean, rtol=1e-6, atol=1e-15)
    # with or without statistics: the same colour
    plain = F.render_frame(sc, 16, spp, 5, 1, 2, 1, gbuffer=gbuffer)
    np.testing.assert_array_equal(plain["color"], got["color"])


def test_film_channels_follow_mitsubas_film(jit):
    # the matched aov integrator's film: its AOVs without the nested integrators' alpha
    mi = jit
    sc = datasets.get_scene("orbit")
    d = sc.frame_dict(mi, 8, 0, 0)
    integ = mi.load_dict(S._matched_integrator(d["integrator"]), optimize=False)
    names = list(integ.aov_names())
    kept = F._film_channels(None, names, names)
    assert kept[:3] == ["color.R", "color.G", "color.B"]
    assert len(kept) == sum(nc for _, _, nc in S.MATCHED_LAYOUT)


def test_the_summing_rule_is_part_of_a_sequences_identity(renderer, monkeypatch):
    before = datasets.scene_fingerprint("flicker", 8)
    monkeypatch.setattr(S, "SAMPLES_VERSION", S.SAMPLES_VERSION + "-other")
    assert datasets.scene_fingerprint("flicker", 8) != before
