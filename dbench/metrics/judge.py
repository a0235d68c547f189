"""The judge: per-pixel error maps → whole-image and surface metrics, error concentration, the
reference's own noise removed, and confidence intervals (README.md, "Metrics").

Every metric dbench reports is the mean of a per-pixel map over a set of pixels, followed by a
scalar function (``rmse = sqrt(mean(sq))``, ``psnr = 10·log10(1 / mean(ldr_sq))``, ...). Keeping
the maps makes three things cheap and exact:

* **surface metrics** (``<metric>_surface``): the same means over the pixels whose emitter
  fraction is 0, so directly visible lights (which hold 89–99 % of the squared error on
  ``cornell``) do not decide the verdict;
* **reference noise**: ``E[(x − r)²] = E[(x − t)²] + v_r``, so
  ``rmse_unbiased = sqrt(max(0, MSE − mean(v_r)))`` and, to first order in v_r/(r² + ε),
  ``relmse_unbiased = max(0, relMSE − mean(v_r / (r² + ε)))``; ``ref_rmse = sqrt(mean(v_r))``.
  Without v_r (a folder's reference whose noise nothing gives, README.md, "Renders from
  another renderer") all three are NaN, "unknown": nothing was removed, so no figure may be
  called unbiased;
* **block bootstrap** (one seed; README.md, "Metrics"): per-block sums of every map, resampled
  with replacement (percentile interval), so B resamples cost one (B × blocks) matrix product;
  the block side adapts to small images (:func:`bootstrap_block`), and with too few blocks
  there is no interval (NaN), never a "± 0".

Maps are (H, W) float64: colour channels (and the time bins of transient videos) are averaged
into the pixel, which leaves every whole-image mean unchanged because each pixel holds the same
number of values. SSIM's map is skimage's, with its border of half a window excluded exactly as
``structural_similarity`` excludes it; FLIP's map is flip_evaluator's. Whole-image values equal
:func:`dbench.metrics.compute_all` (a test holds them within 1e-9).

``top1_share`` = the share of the squared error held by the worst 1 % of pixels (at least one
pixel): near 1, a handful of pixels decide RMSE.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Iterable, Sequence

import numpy as np

from ..errors import DbenchInputError
from .checks import _integrate, check_pair
from .ldr import ssim_global_over
from .params import SSIM_WIN
from .pixel import pixel_mean as _pixel_mean
from .records import METRICS, judge_figures, judged
from .tonemapping import check_ev, tonemap

#: Metrics the judge scores over every pixel and over surface pixels (their records'
#: ``has_surface_variant``; records.py holds each one's per-pixel map).
JUDGED = judged()
#: Extra per-output figures: top1_share and the unbiased forms (records.py).
EXTRA = judge_figures()
#: The metrics whose reference-variance corrected forms the judge writes.
_UNBIASED = tuple(METRICS[n].variant_of for n in EXTRA if METRICS[n].variant == "unbiased")
#: The maps every judgement needs, whatever it scores: those of the figures' base metrics.
_ALWAYS = tuple(dict.fromkeys(METRICS[n].variant_of for n in EXTRA))
#: The relMSE record, whose variance map gives ``ref_relmse_surface``.
_RELMSE = METRICS["relmse"]
#: Side of the square pixel blocks of the bootstrap wherever BOOTSTRAP_MIN_BLOCKS of them fit
#: (64 × 64 px and up): large enough that a denoiser's spatial correlation stays mostly inside
#: a block, so blocks can be resampled as if independent.
BOOTSTRAP_BLOCK = 16
#: Fewest blocks a bootstrap interval is computed from. With one block every resample is the
#: image itself and the interval is exactly 0; with a handful, the resampled means take a
#: handful of values and the percentile interval is too narrow to decide a ranking.
BOOTSTRAP_MIN_BLOCKS = 16
#: Smallest block side on small images. Blocks narrower than a denoiser's footprint split its
#: correlated errors between blocks the bootstrap treats as independent, and the interval comes
#: out too narrow: on a 16-px image under a 5-px box filter, 4-px blocks cover the true RMSE
#: 94 % of the time, 2-px blocks 79 % (tests/run/test_intervals_small.py).
BOOTSTRAP_MIN_SIDE = 4
BOOTSTRAP_RESAMPLES = 1000
CONFIDENCE = 0.95


def _refvar(name: str) -> str:
    """Key of the map of what the reference's variance adds to ``name``'s map."""
    return f"{name}:refvar"


def metric_names(names: Iterable[str] | None = None) -> list[str]:
    """Every column the judge writes for ``names`` (default :data:`JUDGED`): the metrics, their
    ``_surface`` versions, ``top1_share``, ``rmse_unbiased`` and ``relmse_unbiased``."""
    base = [n for n in (JUDGED if names is None else names) if n in JUDGED]
    return base + [f"{n}_surface" for n in base] + list(EXTRA)


@dataclass
class Judgement:
    """One output judged against one reference.

    Attributes:
        values: {column: value} for :func:`metric_names` plus ``ref_rmse`` and
            ``ref_relmse_surface`` = mean over surface pixels of v_r / (r² + ε) (both NaN
            without a reference variance).
        sums: (blocks, maps) per-block sums of every map over all pixels and over surface
            pixels: ``{"all": (sums, counts), "surface": (sums, counts)}``.
        map_names: the order of the maps in ``sums``.
    """

    values: dict[str, float]
    sums: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    map_names: tuple[str, ...] = ()
    #: side of the blocks in ``sums``; None: the image is too small for the bootstrap
    #: (:func:`bootstrap_block`) and ``sums`` holds one block, the whole image
    block: int | None = None


def pixel_maps(output: np.ndarray, reference: np.ndarray, names: Sequence[str],
               reference_var: np.ndarray | None, ev: float
               ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """({map: (H, W)}, {map: (H, W) weight}) of everything ``names`` need (finite ``output``):
    each judged metric's per-pixel map (its record's, keyed by its name) on linear values or
    on the tone-mapped pair, and with ``reference_var`` what the reference's variance adds to
    the maps of the metrics with an unbiased form (keys ``<name>:refvar``)."""
    maps: dict[str, np.ndarray] = {}
    weights: dict[str, np.ndarray] = {}
    ldr = None
    for n in JUDGED:
        if n not in names:
            continue
        m = METRICS[n]
        if m.domain == "ldr":
            if ldr is None:
                ldr = tonemap(_integrate(output), ev), tonemap(_integrate(reference), ev)
            maps[n], weight = m.per_pixel_map(*ldr)
        else:
            maps[n], weight = m.per_pixel_map(output, reference)
        if weight is not None:
            weights[n] = weight
    if reference_var is not None:
        v = np.asarray(reference_var, np.float64)
        for n in _UNBIASED:
            maps[_refvar(n)] = _pixel_mean(METRICS[n].variance(v, reference))
    ones = np.ones(output.shape[:2])
    return maps, {k: weights.get(k, ones) for k in maps}


def _from_means(name: str, mean: dict[str, Any]) -> Any:
    """Metric ``name`` from the means of its maps (scalars or arrays of resamples)."""
    m = METRICS[name]
    with np.errstate(divide="ignore", invalid="ignore"):
        if m.variant == "unbiased":
            base = m.variant_of
            value = np.maximum(0.0, mean[base] - mean[_refvar(base)])
        else:
            value = mean[name]
        return value if m.from_mean is None else m.from_mean(value)


def _needs(name: str) -> tuple[str, ...]:
    m = METRICS[name]
    if m.variant == "unbiased":
        return (m.variant_of, _refvar(m.variant_of))
    return (name,)


def top1_share(sq_map: np.ndarray, fraction: float = 0.01) -> float:
    """Share of Σ ``sq_map`` held by its largest ``fraction`` of pixels (at least one)."""
    flat = np.asarray(sq_map, np.float64).ravel()
    total = float(flat.sum())
    if not np.isfinite(total):
        return float("nan")
    if total <= 0.0:
        return 0.0
    k = max(1, int(math.ceil(fraction * flat.size)))
    top = np.partition(flat, flat.size - k)[flat.size - k:]
    return float(top.sum() / total)


def bootstrap_block(h: int, w: int) -> int | None:
    """Side of the square blocks the one-seed bootstrap resamples on an ``h`` × ``w`` image
    (README.md, "Metrics"): :data:`BOOTSTRAP_BLOCK` (16 px) wherever
    :data:`BOOTSTRAP_MIN_BLOCKS` (16) whole blocks of it fit, so 64 × 64 px and larger keep the
    16-px blocks; on smaller images the largest side of at least :data:`BOOTSTRAP_MIN_SIDE`
    (4) px that fits 16 whole blocks (48 px → 12, 32 → 8, 24 → 6, 16 → 4); None where even
    4-px blocks are fewer than 16 (a square image under 16 px): no interval."""
    for side in range(BOOTSTRAP_BLOCK, BOOTSTRAP_MIN_SIDE - 1, -1):
        if (h // side) * (w // side) >= BOOTSTRAP_MIN_BLOCKS:
            return side
    return None


def _block_sums(maps: dict[str, np.ndarray], weights: dict[str, np.ndarray], select: np.ndarray,
                block: int) -> tuple[np.ndarray, np.ndarray]:
    """(blocks, maps) sums of map·weight·select and of weight·select over square blocks."""
    h, w = select.shape
    by, bx = -(-h // block), -(-w // block)
    names = list(maps)
    sums = np.zeros((by * bx, len(names)))
    counts = np.zeros((by * bx, len(names)))
    ph, pw = by * block - h, bx * block - w

    def blocks(arr: np.ndarray) -> np.ndarray:
        if ph or pw:  # pad only images whose sides are not multiples of the block
            arr = np.pad(arr, ((0, ph), (0, pw)))
        return arr.reshape(by, block, bx, block).sum(axis=(1, 3)).ravel()

    sel = select.astype(np.float64)
    counted: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # maps share weight arrays
    for j, n in enumerate(names):
        key = id(weights[n])
        if key not in counted:
            wt = weights[n] * sel
            counted[key] = (wt, blocks(wt))
        wt, count = counted[key]
        sums[:, j] = blocks(maps[n] * wt)
        counts[:, j] = count
    return sums, counts


def _numbers(name: str, value: Any) -> np.ndarray:
    """``value`` as float64, or a DbenchInputError naming ``name`` (a string, an object)."""
    try:
        return np.asarray(value, np.float64)
    except (TypeError, ValueError):
        raise DbenchInputError(f"{name}: expected an array of numbers, got "
                               f"{type(value).__name__}") from None


def judge(output: Any, reference: Any, *, emitter: Any = None, reference_var: Any = None,
          ev: float = 0.0, names: Iterable[str] | None = None,
          block: int | None = None) -> Judgement:
    """Score ``output`` against ``reference`` (README.md, "Metrics").

    Args:
        output, reference: (H, W, C) images or (H, W, T, C) videos of the same shape.
        emitter: (H, W) or (H, W, 1) emitter fraction of each pixel; pixels with 0 are the
            surface. None: every pixel counts as surface.
        reference_var: variance of the reference mean, same shape as ``reference``, or None
            when unknown (then the unbiased figures, their intervals and ``ref_rmse`` are
            NaN: nothing is removed, and the raw figure is not passed off as unbiased).
        ev: tone-map exposure (stops) of the LDR metrics.
        names: subset of :data:`JUDGED` (default all).
        block: side of the bootstrap's blocks; None: :func:`bootstrap_block` of the image.
    Returns:
        :class:`Judgement`; every value is NaN when ``output`` holds NaN or Inf.
    """
    names = [n for n in (JUDGED if names is None else names)]
    bad = [n for n in names if n not in JUDGED]
    if bad:
        raise DbenchInputError(f"names: unknown judged metric(s) {bad}; valid: {list(JUDGED)}")
    o, r = check_pair(output, reference)
    ev = check_ev(ev)
    h, w = r.shape[:2]
    if emitter is None:
        surface = np.ones((h, w), bool)
    else:
        e = _numbers("emitter", emitter)
        if e.ndim == 3 and e.shape[-1] == 1:
            e = e[..., 0]
        if e.shape != (h, w):
            raise DbenchInputError(f"emitter: expected shape ({h}, {w}, 1), got "
                                   f"{tuple(np.shape(emitter))}")
        if not (np.isfinite(e) & (e >= 0) & (e <= 1)).all():  # a fraction of the footprint
            raise DbenchInputError("emitter: expected values in [0, 1] (the fraction of each "
                                   "pixel that sees a light)")
        surface = ~(e > 0)
    var = None
    if reference_var is not None:
        var = _numbers("reference_var", reference_var)
        if var.shape != r.shape:
            raise DbenchInputError(f"reference_var: expected shape {tuple(r.shape)}, got "
                                   f"{tuple(var.shape)}")
        if not (np.isfinite(var) & (var >= 0)).all():  # (-1 or inf: meaningless unbiased)
            raise DbenchInputError("reference_var: expected finite values >= 0 (the variance "
                                   "of the reference mean); give None where it is unknown")
    if block is None:
        block = bootstrap_block(h, w)
    elif isinstance(block, bool) or not isinstance(block, (int, np.integer)) or block < 1:
        raise DbenchInputError(f"block: expected a whole number of pixels ≥ 1, got {block!r}")
    columns = metric_names(names)
    ref_rmse = float(np.sqrt(var.mean())) if var is not None else float("nan")
    # the reference's own relMSE over surface pixels, set against a method's relmse_surface by
    # the reference-noise warning (dbench.report.verdicts.ref_noise_frame): lights seen
    # directly hold most of the squared error and would hide it
    ref = {"ref_rmse": ref_rmse, "ref_relmse_surface": float(
        _pixel_mean(_RELMSE.variance(var, r))[surface].mean())
        if var is not None and surface.any() else float("nan")}
    if not np.isfinite(o).all():
        return Judgement({**{c: float("nan") for c in columns}, **ref}, block=block)
    # without a reference variance there are no <name>:refvar maps: the unbiased figures
    # come out NaN below and in bootstrap_interval, never equal to the raw ones
    maps, weights = pixel_maps(o, r, names + list(_ALWAYS), var, ev)
    values: dict[str, float] = {}
    # too small for the bootstrap: one block holding the whole image still gives the means
    side = block if block is not None else max(h, w)
    sums = {"all": _block_sums(maps, weights, np.ones((h, w), bool), side),
            "surface": _block_sums(maps, weights, surface, side)}
    map_names = tuple(maps)
    for where, suffix in (("all", ""), ("surface", "_surface")):
        total, count = sums[where][0].sum(0), sums[where][1].sum(0)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = dict(zip(map_names, total / count))
        for n in names:
            values[n + suffix] = float(_from_means(n, mean))
        if where == "all":
            for n in EXTRA:
                if METRICS[n].variant == "unbiased":
                    values[n] = (float(_from_means(n, mean)) if var is not None
                                 else float("nan"))
    for n in EXTRA:
        if METRICS[n].variant == "share":
            values[n] = top1_share(maps[METRICS[n].variant_of])
    if "ssim" in names and min(h, w) < SSIM_WIN and not surface.all():
        # one window covers the image, so its map is one value everywhere and the mean over
        # the surface would be the whole image's SSIM, lights included: the surface form is
        # the same single window over the surface pixels alone
        values["ssim_surface"] = ssim_global_over(tonemap(_integrate(o), ev),
                                                  tonemap(_integrate(r), ev), surface)
    values["ref_rmse"] = ref_rmse
    return Judgement({c: values[c] for c in columns} | ref, sums, map_names, block)


# ---------------------------------------------------------------------------------------------
# Confidence intervals
# ---------------------------------------------------------------------------------------------

def t_interval(values: Sequence[float], confidence: float = CONFIDENCE) -> tuple[float, float]:
    """(mean, half-width) of the Student-t interval ``mean ± t_{(1+c)/2, N−1} · s / √N``.

    Half-width NaN with fewer than two finite values; NaN mean if any value is NaN."""
    from scipy import stats

    x = np.asarray(list(values), np.float64)
    if x.size == 0 or not np.isfinite(x).all():
        return float("nan"), float("nan")
    mean = float(x.mean())
    if x.size < 2:
        return mean, float("nan")
    half = float(stats.t.ppf(0.5 + confidence / 2, x.size - 1) * x.std(ddof=1) / math.sqrt(x.size))
    return mean, half


def interval_over_seeds(per_seed: Sequence[dict[str, float]], columns: Iterable[str]
                        ) -> dict[str, float]:
    """{column: mean, column + "_ci": t half-width} over seeds."""
    out: dict[str, float] = {}
    for c in columns:
        mean, half = t_interval([row.get(c, float("nan")) for row in per_seed])
        out[c], out[c + "_ci"] = mean, half
    return out


def _blocks_with_pixels(frames: Sequence[Judgement], where: str, maps: Sequence[str]) -> int:
    """Fewest blocks, over ``frames`` and ``maps``, that hold a pixel of weight > 0."""
    return min(int((f.sums[where][1][:, f.map_names.index(m)] > 0).sum())
               for f in frames for m in maps)


def bootstrap_interval(frames: Sequence[Judgement], columns: Iterable[str],
                       resamples: int = BOOTSTRAP_RESAMPLES, confidence: float = CONFIDENCE,
                       seed: int = 0) -> dict[str, float]:
    """{column + "_ci": half-width} of the block-bootstrap percentile interval of one seed.

    ``frames`` are the judgements of one output (one for an image, one per scored frame of a
    sequence: the same resampled blocks are used in every frame, and the metric is the mean
    over frames, as in the cell). ``top1_share`` is not a mean of blocks and gets NaN.
    Deterministic (fixed generator seed) so that reports are reproducible.

    A column whose pixels fall in fewer than :data:`BOOTSTRAP_MIN_BLOCKS` blocks (an image too
    small for :func:`bootstrap_block`, or surface pixels in only a few blocks) gets NaN, "no
    interval", never 0: resampling so few blocks says nothing about the spread (README.md,
    "Metrics").
    """
    columns = list(columns)
    out = {c + "_ci": float("nan") for c in columns}
    frames = [f for f in frames if f.sums]
    if not frames:
        return out
    nb = frames[0].sums["all"][0].shape[0]
    if nb < BOOTSTRAP_MIN_BLOCKS:
        return out
    rng = np.random.default_rng(seed)
    picks = rng.integers(0, nb, size=(resamples, nb))
    weights = np.zeros((resamples, nb))
    np.add.at(weights, (np.repeat(np.arange(resamples), nb), picks.ravel()), 1.0)
    lo_q, hi_q = 50 * (1 - confidence), 50 * (1 + confidence)
    for where, suffix in (("all", ""), ("surface", "_surface")):
        per_frame = []
        for f in frames:
            s, c = f.sums[where]
            with np.errstate(invalid="ignore", divide="ignore"):
                per_frame.append(dict(zip(f.map_names, ((weights @ s) / (weights @ c)).T)))
        for col in columns:
            base = col[:-len(suffix)] if suffix and col.endswith(suffix) else col
            if suffix and not col.endswith(suffix):
                continue
            if not suffix and col.endswith("_surface"):
                continue
            if base not in JUDGED and getattr(METRICS.get(base), "variant", None) != "unbiased":
                continue
            # a frame whose reference variance is unknown has no refvar maps: no interval
            if any(m not in pf for pf in per_frame for m in _needs(base)):
                continue
            if _blocks_with_pixels(frames, where, _needs(base)) < BOOTSTRAP_MIN_BLOCKS:
                continue
            boot = np.mean([np.asarray(_from_means(base, pf), np.float64) for pf in per_frame],
                           axis=0)
            boot = boot[np.isfinite(boot)]
            if boot.size >= resamples // 2:
                lo, hi = np.percentile(boot, [lo_q, hi_q])
                out[col + "_ci"] = float((hi - lo) / 2)
    return out


def block_of(frames: Sequence[Judgement]) -> int | None:
    """The bootstrap block side of one output's judgements (None: too small, or none)."""
    return frames[0].block if len(frames) else None


def ci_kind(n_seeds: int, block: int | None = BOOTSTRAP_BLOCK,
            resamples: int = BOOTSTRAP_RESAMPLES) -> str:
    """The words that say which interval a cell carries; ``block`` None: one seed on an image
    too small for the block bootstrap (:func:`bootstrap_block`), so no interval."""
    if n_seeds >= 2:
        return f"t 95 % over {n_seeds} seeds"
    if block is None:
        return (f"no interval (one seed, and the image holds fewer than {BOOTSTRAP_MIN_BLOCKS} "
                f"blocks of {BOOTSTRAP_MIN_SIDE} px for a block bootstrap; use --seeds 2 or "
                f"more)")
    return f"block bootstrap 95 % ({block}-px blocks, {resamples} resamples, one seed)"


__all__ = ["JUDGED", "EXTRA", "Judgement", "judge", "metric_names", "top1_share", "t_interval",
           "interval_over_seeds", "bootstrap_interval", "bootstrap_block", "block_of", "ci_kind",
           "pixel_maps", "BOOTSTRAP_BLOCK", "BOOTSTRAP_MIN_BLOCKS", "BOOTSTRAP_MIN_SIDE"]
