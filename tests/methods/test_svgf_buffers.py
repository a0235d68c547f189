"""svgf and asvgf buffers (docs/methods/svgf.md §2, §5, §9): emission accumulated, the
edge-stopping normal chosen, demodulation bounded at zero and tiny albedo, the luminance weight."""
import numpy as np
import pytest
from dbench import registry
from dbench.run.sequence_run import run_sequence
from dbench.synthetic import synthetic_sequence
from dbench.errors import DbenchInputError
from dbench.methods import svgf as C


def test_emission_is_accumulated_not_added_raw():
    """An aliased emitter edge (a 1-spp sample sees the lamp in one frame, not in the next):
    the output's emission converges to the coverage instead of flickering with the sample."""
    h, w = 8, 8
    seq = synthetic_sequence(h, w, frames=12, shift=0)
    m = registry.get("svgf")
    m.reset()
    outs = []
    for i, f in enumerate(seq):
        emi = np.zeros((h, w, 3), np.float32)
        if i % 2 == 0:
            emi[2:4, 2:4] = 40.0
        outs.append(m.denoise(f.with_buffers(color=f.color + emi, emission=emi)))
    lamp = np.array([o[2:4, 2:4].mean() for o in outs[6:]])
    assert np.all(np.abs(np.diff(lamp)) < 10.0)          # raw emission would jump by 40
    assert 10.0 < lamp.mean() < 30.0                     # about the coverage 20
    assert "emission" in registry.get("svgf").optional_needs


def test_normal_buffer_chooses_the_edge_stopping_normal():
    """``normal_buffer``: the à-trous and spatial-variance weights read the chosen buffer (seed
    001 §1.2.1's reflected or geometric normal); reprojection keeps the shading normal. Equal
    buffers give equal output, a different one changes the filtering, a missing one is refused."""
    from dbench.synthetic import synthetic_sequence
    from dbench.errors import DbenchInputError

    seq = synthetic_sequence(24, 32, frames=3)
    rng = np.random.default_rng(2)
    other = rng.normal(size=seq[0].normal.shape).astype(np.float32)
    other /= np.linalg.norm(other, axis=-1, keepdims=True)
    outs = {}
    for label, buffer, value in (("default", "normal", None), ("same", "reflected_normal", "n"),
                                 ("other", "geo_normal", other)):
        m = registry.get("svgf", normal_buffer=buffer)
        m.reset()
        for f in seq:
            extra = {} if value is None else {buffer: f.normal if isinstance(value, str) else value}
            out = m.denoise(f.with_buffers(**extra))
        outs[label] = out
    np.testing.assert_array_equal(outs["default"], outs["same"])
    assert np.abs(outs["other"] - outs["default"]).max() > 1e-3
    with pytest.raises(DbenchInputError, match="geo_normal"):
        registry.get("asvgf", normal_buffer="geo_normal").denoise(seq[0])
    with pytest.raises(DbenchInputError, match="normal_buffer"):
        registry.get("svgf", normal_buffer="mirror")


@pytest.mark.parametrize("name", ["svgf", "asvgf"])
@pytest.mark.parametrize("backend", ["numba", "reference"])
def test_without_an_emission_buffer_the_emission_history_is_left_out(name, backend):
    """No ``emission`` buffer: the emission is 0 everywhere, so its three history planes are
    neither reprojected nor accumulated; the output equals the one with a zero buffer."""
    seq = synthetic_sequence(24, 40, frames=4)
    zero = np.zeros((24, 40, 3), np.float32)
    a, b = (registry.get(name, backend=backend) for _ in range(2))
    a.reset()
    b.reset()
    for f in seq:
        np.testing.assert_array_equal(a.denoise(f), b.denoise(f.with_buffers(emission=zero)))
    assert b.history.buffers.shape[0] == a.history.buffers.shape[0] + 3


def test_demodulation_albedo_is_continuous_and_bounded_on_every_backend():
    """a_eff = clip(albedo, ALBEDO_FLOOR, 1) where finite, else 1 (docs/temporal.md §12): no
    jump between albedo 0 and albedo just above 1e-3 (the spec's rule gave 1 and 0.001)."""
    from dbench.methods.svgf.params import ALBEDO_FLOOR

    values = np.array([0.0, 1e-4, 2e-3, 0.05, ALBEDO_FLOOR, 0.5, 1.5, np.nan, np.inf, -0.2],
                      np.float32)
    albedo = np.repeat(values[None, :, None], 3, axis=2)          # (1, 10, 3)
    want = np.array([ALBEDO_FLOOR] * 5 + [0.5, 1.0, 1.0, 1.0, ALBEDO_FLOOR], np.float32)
    color = np.ones((1, values.size, 3), np.float32)
    hit = np.ones((1, values.size), bool)
    for backend in ("reference", "numba", "torch"):
        pr = C.prepare(backend, color, albedo, None, hit)
        np.testing.assert_allclose(pr["a_eff"][:, 0], np.tile(want, (3, 1)), rtol=1e-6,
                                   err_msg=backend)
        assert pr["illum"].max() <= 1.0 / ALBEDO_FLOOR + 1e-4
    np.testing.assert_allclose(C.prepare("numba", color, albedo, None, hit, 0.3)["a_eff"][:, 0, :5],
                               0.3, rtol=1e-6)
    with pytest.raises(DbenchInputError, match="albedo_floor"):
        registry.get("svgf", albedo_floor=0.0)
    with pytest.raises(DbenchInputError, match=r"albedo_floor: expected a number in \[0.001, 1\]"):
        registry.get("bmfr", albedo_floor=1e-45)  # 1 / a subnormal floor overflows float32
    assert registry.get("asvgf", albedo_floor=1e-3).params["albedo_floor"] == 1e-3


@pytest.mark.parametrize("name", ["svgf", "asvgf", "bmfr"])
def test_pixels_with_zero_and_tiny_albedo_side_by_side_stay_bounded(name):
    """A surface whose 1-spp albedo samples are 0 (a conductor's AOV) in some pixels and 0.002
    (a dark reflection's PSR albedo) in others, changing from frame to frame: the spec's rule
    demodulated them by 1 and by 0.002, the filters mixed illumination 500x apart, and pixels
    came out hundreds of times too bright (found on the autoencoder's training sequences)."""
    from dbench.data import Sequence

    seq = synthetic_sequence(32, 40, frames=10)
    rng = np.random.default_rng(3)
    frames = []
    for f in seq:
        albedo = np.where(rng.random(f.albedo.shape[:2])[..., None] < 0.5, 0.0, 0.002)
        frames.append(f.with_buffers(albedo=np.broadcast_to(albedo, f.albedo.shape)
                                     .astype(np.float32), emission=None))
    r = run_sequence(name, Sequence(frames), warmup=4, keep_outputs=True)
    for out, f in zip(r.outputs[4:], frames[4:]):
        assert np.isfinite(out).all()
        assert out.max() < 3.0 * f.reference.max()


def test_gaussian_luminance_weight_is_the_square_of_the_laplacian_exponent():
    """w_l = exp(−d²) ("gaussian", the dbench preset) against exp(−d) ("laplacian", the paper's):
    one tap, no normal or depth difference, d = |Δl| / (σ_l √(g(Var)) + ε) = 0.5 and 2."""
    h, w = 1, 2
    z = np.ones((h, w), np.float32)
    n = np.zeros((3, h, w), np.float32)
    n[2] = 1
    hit = np.ones((h, w), bool)
    g0 = np.zeros((h, w), np.float32)
    var = np.full((h, w), 1.0, np.float32)     # σ_l √(1 + ε) ≈ 4: d = Δl / 4
    for dl in (2.0, 8.0):
        c = np.zeros((3, h, w), np.float32)
        c[:, 0, 1] = dl                          # luminance of grey = its value
        for kernel, power in (("laplacian", 1), ("gaussian", 2)):
            out, _ = C.atrous_reference(c, var, z, g0, g0, n, hit, hit, hit, 1, sigma_z=1e30,
                                        eps_var=0.0, lum_kernel=kernel)
            d = dl / 4.0
            wt = C.H1[3] * C.H1[2] * np.exp(-d ** power) / (C.H1[2] * C.H1[2])
            assert out[0, 0, 0] == pytest.approx(dl * wt / (1 + wt), rel=1e-6)
    with pytest.raises(DbenchInputError, match="luminance_kernel"):
        registry.get("svgf", luminance_kernel="box")
