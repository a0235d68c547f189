"""Numerical stress test: every registered method against adversarial inputs.

A case passes when the method shows the documented behaviour:

* finite output of the input's shape wherever the input is finite — a non-finite input pixel may
  stay non-finite in its own output pixel only (it is "missing"), never spread to another pixel;
* or a :class:`~dbench.errors.DbenchInputError` whose message names the offending buffer and the
  expected shape (the only acceptable error, and only for cases where input is invalid).

Transient cases (``tr_*``) build (H, W, T, 3) :class:`~dbench.data.TransientFrame` videos; a
method without ``transient`` among its kinds reports n/a for them (and a transient-only method
for the steady cases).

Every case states its expected behaviour next to it (``Case.expect``; rendered in stress.md).
Sequence methods run ``reset()`` and then the same frame twice: the first frame after
``reset()`` (no history: spatial variance, first-frame paths) and the second (reprojected
history) are judged separately and must both pass.

Anything else fails: another exception, a wrong shape or dtype, NaN spread, or more than
``TIME_LIMIT_S`` seconds on a tiny image (twice: calls over it are timed again, since a
method's first call in a process compiles its kernels). ``dbench stress`` writes ``results/stress.md``; the same
cases run in pytest (tests/stress/test_stress.py).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..data import Frame, SampleStats, TransientFrame
from ..synthetic import base_frame, base_video

TIME_LIMIT_S = 60.0


@dataclass(frozen=True)
class Case:
    name: str
    description: str
    build: Callable[[], Frame]
    error_ok: tuple[str, ...] = ()   # buffers an error may name (invalid input)
    needs_buffer: str | None = None  # case applies only to methods needing this buffer
    kind: str = "steady"             # "transient" cases build a TransientFrame
    strict: bool = True              # False: accepting the missing buffer is also documented
    expect: str = "finite output"    # the documented behaviour, rendered in stress.md
    all_methods: bool = False        # run for every method, not only those needing needs_buffer
                                     # (then only a method needing it may refuse)


def _with_color(frame: Frame, color: np.ndarray, stats_mean: np.ndarray | None = None) -> Frame:
    st = frame.stats
    stats = SampleStats(n=st.n, mean=color if stats_mean is None else stats_mean,
                        var_mean=st.var_mean, m3=st.m3, transform=st.transform, lam=st.lam)
    return frame.with_buffers(color=color, stats=stats)


def _nan_pixels(value: float) -> Callable[[], Frame]:
    def build() -> Frame:
        f = base_frame()
        c = f.color.copy()
        c[5, 7] = value
        c[12, 12, 1] = value
        mean = f.stats.mean.copy()
        mean[5, 7] = value
        mean[12, 12, 1] = value
        return _with_color(f, c, mean)
    return build


def _firefly() -> Frame:
    f = base_frame()
    c = f.color.copy()
    c[10, 10] = 1e6
    return _with_color(f, c)


def _negative() -> Frame:
    f = base_frame()
    c = f.color.copy()
    c[::3, ::4] = -0.5
    return _with_color(f, c)


def _constant(value: float) -> Callable[[], Frame]:
    def build() -> Frame:
        f = base_frame()
        c = np.full_like(f.color, value)
        st = SampleStats(n=f.stats.n, mean=c, var_mean=np.zeros_like(c, np.float64),
                         m3=np.zeros_like(c, np.float64), transform="identity", lam=1.0)
        return f.with_buffers(color=c, stats=st)
    return build


def _tiny(scale: float) -> Callable[[], Frame]:
    """The base frame's radiance (colour, statistics, reference) times ``scale``: at 1e-20 its
    variances (≈ 1e-42) are subnormal in float32, where 1 / x overflows to +Inf."""
    def build() -> Frame:
        f = base_frame()
        st = f.stats
        stats = SampleStats(n=st.n, mean=st.mean * scale, var_mean=st.var_mean * scale ** 2,
                            m3=st.m3 * scale ** 3, transform=st.transform, lam=st.lam)
        return f.with_buffers(color=(f.color * scale).astype(f.color.dtype), stats=stats,
                              reference=(f.reference * scale).astype(np.float32))
    return build


def _zero_variance() -> Frame:
    f = base_frame()
    st = SampleStats(n=f.stats.n, mean=f.stats.mean, var_mean=np.zeros_like(f.stats.var_mean),
                     m3=np.zeros_like(f.stats.m3), transform="identity", lam=1.0)
    return f.with_buffers(stats=st)


def _size(h: int, w: int) -> Callable[[], Frame]:
    return lambda: base_frame(h, w)


def _dtype(dtype) -> Callable[[], Frame]:
    def build() -> Frame:
        f = base_frame()
        return Frame(color=f.color.astype(dtype), albedo=f.albedo.astype(dtype),
                     normal=f.normal.astype(dtype), depth=f.depth.astype(dtype),
                     position=f.position.astype(dtype), stats=f.stats, reference=f.reference)
    return build


def _non_contiguous() -> Frame:
    big = base_frame(48, 48)
    views = {k: getattr(big, k)[::2, ::2] for k in ("color", "albedo", "normal", "depth",
                                                    "position", "reference")}
    st = big.stats
    stats = SampleStats(n=st.n[::2, ::2], mean=st.mean[::2, ::2], var_mean=st.var_mean[::2, ::2],
                        m3=st.m3[::2, ::2], transform=st.transform, lam=st.lam)
    return Frame(stats=stats, **views)


def _flat_wall() -> Frame:
    f = base_frame()
    h, w = f.shape
    normal = np.zeros((h, w, 3))
    normal[..., 2] = 1
    position = np.zeros((h, w, 3))
    position[..., 0] = 0.3
    return f.with_buffers(albedo=np.full((h, w, 3), 0.5), normal=normal, position=position,
                          depth=np.full((h, w, 1), 2.0))


def _missing(buffer: str) -> Callable[[], Frame]:
    return lambda: base_frame().with_buffers(**{buffer: None})


def _bright(value: float) -> Callable[[], Frame]:
    """One pixel (every channel, colour and statistics) at a huge but finite ``value``."""
    def build() -> Frame:
        f = base_frame()
        c = f.color.copy()
        c[10, 10] = value
        mean = f.stats.mean.copy()
        mean[10, 10] = value
        return _with_color(f, c, mean)
    return build


def _nan_albedo() -> Frame:
    f = base_frame()
    return f.with_buffers(albedo=np.full(f.color.shape, np.nan, np.float32))


def _zero_normals() -> Frame:
    f = base_frame()
    return f.with_buffers(normal=np.zeros(f.color.shape, np.float32))


def _stats_n1() -> Frame:
    """One sample per pixel: n = 1, σ² undefined so var_mean = 0 (SampleStats convention), a
    Welch test with ν = n_i + n_j − 2 = 0 degrees of freedom."""
    f = base_frame()
    mean = f.stats.mean
    st = SampleStats(n=np.ones_like(mean), mean=mean, var_mean=np.zeros_like(mean),
                     m3=np.zeros_like(mean), transform="identity", lam=1.0)
    return f.with_buffers(stats=st)


def _stats_huge_var() -> Frame:
    """n = 1 in the left half with an (inconsistent) huge variance 1e30 and third moment 1e45
    everywhere: the skew correction, the Welch t and the ProDen gate must stay finite."""
    f = base_frame()
    mean = f.stats.mean
    n = np.full(mean.shape, 16.0)
    n[:, : mean.shape[1] // 2] = 1.0
    st = SampleStats(n=n, mean=mean, var_mean=np.full(mean.shape, 1e30),
                     m3=np.full(mean.shape, 1e45), transform="identity", lam=1.0)
    return f.with_buffers(stats=st)


def _transformed(transform: str, lam: float, negative: bool = False) -> Callable[[], Frame]:
    """Statistics of 8 samples per pixel under ``transform`` with λ = ``lam`` (computed by
    dbench.datasets.stats.stats_from_samples); ``negative``: a third of the samples below 0."""
    def build() -> Frame:
        from ..datasets.stats import stats_from_samples
        f = base_frame()
        rng = np.random.default_rng(1)
        ref = f.reference.astype(np.float64)
        samples = ref[None] * rng.exponential(1.0, (8,) + ref.shape)
        if negative:
            samples -= rng.uniform(0.0, 1.0, samples.shape) * (rng.random(samples.shape) < 0.33)
        st = stats_from_samples(samples, transform, lam)
        return f.with_buffers(color=samples.mean(0).astype(np.float32), stats=st)
    return build


FINITE = "finite output"
FINITE_BOTH = "finite output on the first and the second frame after reset()"


def _refuse(buffer: str) -> str:
    return f"DbenchInputError naming `{buffer}` from methods that list it in `needs`"


CASES: tuple[Case, ...] = (
    # expected: finite output except at the missing pixel itself (it may stay non-finite)
    Case("nan", "NaN pixels in color and stats", _nan_pixels(np.nan),
         expect="finite output; the NaN pixels may stay non-finite in their own output pixel"),
    Case("inf", "+Inf pixels in color and stats", _nan_pixels(np.inf),
         expect="finite output; the Inf pixels may stay non-finite in their own output pixel"),
    Case("neg_inf", "-Inf pixels in color and stats", _nan_pixels(-np.inf),
         expect="finite output; the -Inf pixels may stay non-finite in their own output pixel"),
    Case("negative", "negative radiance values", _negative, expect=FINITE),
    Case("firefly", "one pixel at 1e6", _firefly, expect=FINITE),
    # bright but finite: overflow of squares (moments, variances), log transforms, QR norms
    Case("bright_1e10", "one pixel at 1e10 (colour and stats)", _bright(1e10),
         expect=FINITE_BOTH),
    Case("bright_1e20", "one pixel at 1e20 (colour and stats; its square overflows float32)",
         _bright(1e20), expect=FINITE_BOTH),
    Case("bright_3e38", "one pixel at 3e38, near the float32 maximum (colour and stats)",
         _bright(3e38), expect=FINITE_BOTH),
    Case("zeros", "all-zero image, zero variance", _constant(0.0), expect=FINITE),
    Case("tiny_1e-20", "radiance × 1e-20 (colour and statistics; its variances are subnormal "
         "in float32)", _tiny(1e-20), expect=FINITE),
    Case("constant", "constant image 0.5, zero variance", _constant(0.5), expect=FINITE),
    Case("zero_variance", "noisy color with zero-variance statistics", _zero_variance,
         expect=FINITE),
    Case("stats_n1", "one sample per pixel (n = 1, var_mean = 0, ν = 0 in the Welch test)",
         _stats_n1, expect=FINITE),
    Case("stats_huge_var", "n = 1 on half the image, var_mean 1e30 and m3 1e45 everywhere",
         _stats_huge_var, expect=FINITE),
    Case("boxcox_lam0", "Box-Cox statistics with λ = 1e-6 (≈ log)",
         _transformed("box-cox", 1e-6), expect=FINITE),
    Case("boxcox_lam1", "Box-Cox statistics with λ = 0.999999 (≈ shifted identity)",
         _transformed("box-cox", 0.999999), expect=FINITE),
    Case("yeojohnson_negative", "Yeo-Johnson statistics (λ = 0.5) of samples a third of which "
         "are negative", _transformed("yeo-johnson", 0.5, negative=True), expect=FINITE),
    Case("yeojohnson_lam2", "Yeo-Johnson statistics with λ = 2 (log branch for negatives) of "
         "partly negative samples", _transformed("yeo-johnson", 2.0, negative=True),
         expect=FINITE),
    Case("size_1x1", "1×1 image", _size(1, 1), expect=FINITE),
    Case("size_1xN", "1×17 image", _size(1, 17), expect=FINITE),
    Case("size_Nx1", "17×1 image", _size(17, 1), expect=FINITE),
    Case("size_prime", "13×29 image", _size(13, 29), expect=FINITE),
    Case("float16", "float16 buffers", _dtype(np.float16), expect=FINITE),
    Case("float64", "float64 buffers", _dtype(np.float64), expect=FINITE),
    Case("non_contiguous", "strided (non-contiguous) views", _non_contiguous, expect=FINITE),
    Case("flat_wall", "rank-deficient features: constant normal, albedo and position",
         _flat_wall, expect=FINITE),
    Case("nan_albedo", "albedo all NaN (every pixel: demodulate by 1 / isolated feature)",
         _nan_albedo, ("albedo",), "albedo", strict=False,
         expect="finite output everywhere, or DbenchInputError naming `albedo`"),
    Case("zero_normals", "zero-length normals everywhere", _zero_normals, expect=FINITE),
    Case("missing_albedo", "albedo buffer absent", _missing("albedo"), ("albedo",), "albedo",
         expect=_refuse("albedo")),
    Case("missing_normal", "normal buffer absent", _missing("normal"), ("normal",), "normal",
         expect=_refuse("normal")),
    Case("missing_depth", "depth buffer absent", _missing("depth"), ("depth",), "depth",
         expect=_refuse("depth")),
    Case("missing_stats", "statistics absent", _missing("stats"), ("stats",), "stats",
         expect=_refuse("stats")),
    Case("missing_position", "position buffer absent", _missing("position"), ("position",),
         "position", expect=_refuse("position")),
    # emitter is optional (no built-in method lists it): every method must run without it
    Case("missing_emitter", "emitter buffer absent (optional per-pixel light coverage)",
         _missing("emitter"), ("emitter",), "emitter", all_methods=True,
         expect="finite output; " + _refuse("emitter")),
    Case("missing_motion", "motion vectors absent (error, or no reprojection: history reset "
         "every frame)", _missing("motion"), ("motion",), "motion", strict=False,
         expect="DbenchInputError naming `motion`, or finite output without reprojection"),
    Case("missing_gradient", "A-SVGF gradient frame absent", _missing("gradient"),
         ("gradient",), "gradient", expect=_refuse("gradient")),
)


def _as_sequence_frame(frame: Frame, case: Case) -> Frame:
    """Give a steady stress frame what a sequence method needs to use its history: zero motion
    (a static camera) and a gradient frame equal to the color (unchanged lights), so the second
    call reprojects and blends the first frame's outputs. The buffer a ``missing_*`` case
    removes stays absent."""
    h, w = frame.shape
    extra = {}
    if case.needs_buffer != "motion" and not frame.has("motion"):
        extra["motion"] = np.zeros((h, w, 2), np.float32)
    if case.needs_buffer != "gradient" and not frame.has("gradient"):
        extra["gradient"] = np.array(frame.color, copy=True)
    return frame.with_buffers(**extra) if extra else frame


# ---------------------------------------------------------------------------------------------
# transient cases: (H, W, T, 3) videos; methods without "transient" in their kinds are n/a


def _video_with(frame: TransientFrame, color: np.ndarray) -> TransientFrame:
    st = frame.stats
    stats = SampleStats(n=st.n, mean=color, var_mean=st.var_mean, m3=st.m3,
                        transform=st.transform, lam=st.lam)
    return frame.with_buffers(color=color, stats=stats)


def _video_values(value: float) -> Callable[[], TransientFrame]:
    def build() -> TransientFrame:
        f = base_video()
        c = f.color.copy()
        c[4, 5, 3] = value
        c[7, 2, 6, 1] = value
        return _video_with(f, c)
    return build


def _video_bright(value: float) -> Callable[[], TransientFrame]:
    """One voxel (one pixel, one bin, every channel, colour and statistics) at ``value``."""
    def build() -> TransientFrame:
        f = base_video()
        c = f.color.copy()
        c[4, 5, 3] = value
        return _video_with(f, c)
    return build


def _video_all_empty() -> TransientFrame:
    f = base_video()
    z = np.zeros_like(f.color)
    st = SampleStats(n=f.stats.n, mean=z, var_mean=np.zeros_like(z, np.float64),
                     m3=np.zeros_like(z, np.float64), transform="identity", lam=1.0)
    return f.with_buffers(color=z, stats=st, reference=z)


def _video_size(h: int, w: int, t: int) -> Callable[[], TransientFrame]:
    return lambda: base_video(h, w, t)


def _video_missing(buffer: str) -> Callable[[], TransientFrame]:
    return lambda: base_video().with_buffers(**{buffer: None})


TRANSIENT_CASES: tuple[Case, ...] = (
    Case("tr_all_empty", "transient: every bin empty (all zeros)", _video_all_empty,
         kind="transient", expect=FINITE),
    Case("tr_nan_voxel", "transient: NaN voxels in color and stats", _video_values(np.nan),
         kind="transient", expect="finite output; the NaN voxels may stay non-finite"),
    Case("tr_inf_voxel", "transient: +Inf voxels in color and stats", _video_values(np.inf),
         kind="transient", expect="finite output; the Inf voxels may stay non-finite"),
    Case("tr_firefly", "transient: one voxel at 1e6", _video_values(1e6), kind="transient",
         expect=FINITE),
    Case("tr_bright_1e10", "transient: one voxel (one bin) at 1e10", _video_bright(1e10),
         kind="transient", expect=FINITE),
    Case("tr_bright_1e20", "transient: one voxel (one bin) at 1e20", _video_bright(1e20),
         kind="transient", expect=FINITE),
    Case("tr_bright_3e38", "transient: one voxel (one bin) at 3e38", _video_bright(3e38),
         kind="transient", expect=FINITE),
    Case("tr_negative", "transient: negative values", _video_values(-0.5), kind="transient",
         expect=FINITE),
    Case("tr_one_bin", "transient: a single time bin (T = 1)", _video_size(12, 12, 1),
         kind="transient", expect=FINITE),
    Case("tr_size_1x1", "transient: 1×1 pixel, 6 bins", _video_size(1, 1, 6), kind="transient",
         expect=FINITE),
    # G-buffers are optional for transient methods (media videos have none, docs/methods/statistical.md
    # §11.3): an error naming albedo or a finite output both pass
    Case("tr_missing_albedo", "transient: albedo absent (error or G-buffer-free fallback)",
         _video_missing("albedo"), ("albedo",), "albedo", kind="transient", strict=False,
         expect="DbenchInputError naming `albedo`, or finite output (G-buffer-free fallback)"),
    Case("tr_missing_stats", "transient: statistics absent", _video_missing("stats"),
         ("stats",), "stats", kind="transient", expect=_refuse("stats")),
)
CASES = CASES + TRANSIENT_CASES


