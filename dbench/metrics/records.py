"""One record per metric (README.md, "Metrics"; docs/metrics.md §1): everything dbench knows
about a metric, in one place, and read from here by every module that names metrics.

A :class:`Metric` holds the metric's name, the one-line definition the reports print, its
direction, whether it reads linear HDR values or the tone-mapped image, its range, its kind,
whether ``--rank-by`` accepts it, which headline tables show it, and its formula: the per-value
error map whose mean it is (:func:`metrics.compute`, :func:`metrics.per_bin`), the judge's
per-pixel map and the function of the map's mean. A metric with ``has_surface_variant`` gets a
derived record ``<name>_surface`` (the same mean over the pixels that do not see a light), one
with ``has_unbiased_variant`` a derived ``<name>_unbiased`` (the reference's own variance
removed); ``top1_share`` is a figure of rmse's squared-error map.

:data:`METRICS` holds every record in report order: the image metrics, their surface forms, the
judge's figures of them (top1_share, the unbiased forms), then the sequence metrics. Adding a
metric is one :class:`Metric` in ``_RECORDS`` (and its test in tests/metrics/): the compute
functions, the judge, the cell columns, the directions, ``--rank-by``, the headline tables and
the definitions printed in reports all read it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Callable

import numpy as np

from .hdr import _hdrflip_value
from .ldr import _flip_map, _psnr_from_mean, _ssim_map, flip_ldr, psnr_ldr, ssim_ldr
from .params import RELMSE_EPS, RMAE_EPS, SMAPE_EPS
from .pixel import (_err_rel_sq, _err_rmae, _err_smape, _err_sq, _var_rel_sq, _var_sq,
                    pixel_mean)
from .tonemapping import TONEMAP_DEFINITION
from .video_quality import CVVDP_DEFINITION

#: Kinds of metric: one output against its reference (steady images, transient videos), the
#: frame-to-frame differences of a sequence, a whole sequence.
KINDS = ("image", "temporal", "video")
#: Kinds of run whose headline tables a metric may be in ("steady": also the run report of a
#: transient run; "transient": the published transient sweeps).
RUNS = ("steady", "sequence", "transient")
_ALL_RUNS = frozenset(RUNS)
#: Derived forms, in the order their columns follow the image metrics.
VARIANTS = ("surface", "share", "unbiased")


@dataclass(frozen=True)
class Metric:
    """Everything about one metric.

    Attributes:
        name: the column and ``compute`` name.
        definition: the line the reports print (None: none printed).
        higher_is_better: direction (otherwise lower is better, 0 is perfect).
        domain: ``"hdr"`` (linear HDR values) or ``"ldr"`` (the tone-mapped image T(x)).
        range: (lowest, highest) value.
        kind: one of :data:`KINDS`.
        rankable: ``--rank-by`` accepts it.
        headline: the runs (:data:`RUNS`) whose headline table shows it.
        surface_headline: the runs whose headline table shows ``<name>_surface``.
        error_map: per-value error ``(x, r[, eps]) -> array`` on the metric's domain; the
            metric is ``from_mean`` of its mean over every value.
        eps: default ε of ``error_map`` (and the ``eps`` option of ``compute``); None: no ε.
        per_pixel_map: ``(x, r) -> ((H, W) map, (H, W) weight or None)``, the judge's map
            (default: :func:`pixel.pixel_mean` of ``error_map``; None without one).
        from_mean: the metric from the mean of its map, scalars or arrays (None: the mean).
        image_fn: the whole-image value ``compute`` takes for a metric that is not the mean of
            an ``error_map`` over linear values: ``(T(x), T(r))`` for ``"ldr"``, the checked
            linear arrays for ``"hdr"``.
        channels: channel counts the metric accepts (empty: any).
        has_surface_variant: the judge scores it over every pixel and over the surface
            (``<name>_surface``); every such metric is in every cell.
        has_unbiased_variant: ``<name>_unbiased`` removes the reference's variance, whose
            per-value map is ``variance_map`` and whose definition ``unbiased_definition``.
        variant_of, variant: for derived records, the base metric and the form
            (:data:`VARIANTS`).
    """

    name: str
    definition: str | None
    higher_is_better: bool = False
    domain: str = "hdr"
    range: tuple[float, float] = (0.0, math.inf)
    kind: str = "image"
    rankable: bool = False
    headline: frozenset[str] = frozenset()
    surface_headline: frozenset[str] = frozenset()
    error_map: Callable[..., np.ndarray] | None = field(default=None, repr=False)
    eps: float | None = None
    per_pixel_map: Callable[..., tuple[np.ndarray, Any]] | None = field(default=None,
                                                                        repr=False)
    from_mean: Callable[[Any], Any] | None = field(default=None, repr=False)
    image_fn: Callable[..., float] | None = field(default=None, repr=False)
    channels: tuple[int, ...] = ()
    has_surface_variant: bool = False
    has_unbiased_variant: bool = False
    variance_map: Callable[..., np.ndarray] | None = field(default=None, repr=False)
    unbiased_definition: str | None = None
    variant_of: str | None = None
    variant: str | None = None

    def __post_init__(self) -> None:
        if self.kind not in KINDS or self.domain not in ("hdr", "ldr"):
            raise ValueError(f"{self.name}: kind {self.kind!r} / domain {self.domain!r}")
        if not set(self.headline | self.surface_headline) <= _ALL_RUNS:
            raise ValueError(f"{self.name}: headline runs must be among {RUNS}")
        if self.per_pixel_map is None and self.error_map is not None:
            object.__setattr__(self, "per_pixel_map", self._mean_map)
        if self.has_surface_variant and self.per_pixel_map is None:
            raise ValueError(f"{self.name}: a surface form needs a per-pixel map")
        if self.has_unbiased_variant and (self.variance_map is None or self.error_map is None
                                          or self.unbiased_definition is None):
            raise ValueError(f"{self.name}: an unbiased form needs error and variance maps "
                             f"and a definition")

    def errors(self, x: np.ndarray, r: np.ndarray, eps: float | None = None) -> np.ndarray:
        """The per-value error map (``eps`` None: the default ε)."""
        if self.eps is None:
            return self.error_map(x, r)
        return self.error_map(x, r, self.eps if eps is None else eps)

    def variance(self, v: np.ndarray, r: np.ndarray) -> np.ndarray:
        """The per-value map of what the reference's variance ``v`` adds to :meth:`errors`."""
        if self.eps is None:
            return self.variance_map(v, r)
        return self.variance_map(v, r, self.eps)

    def _mean_map(self, x: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, None]:
        return pixel_mean(self.errors(x, r)), None


def _image(name: str, definition: str, **kw: Any) -> Metric:
    return Metric(name, definition, kind="image", **kw)


_LINEAR = "; linear HDR values"
_ON_SUM = "; transient: on the sum over T"
_STEADY_HEADLINE = frozenset({"steady"})

_RECORDS: tuple[Metric, ...] = (
    _image("mse", "MSE = mean((x − r)²) over all pixels, bins and channels" + _LINEAR,
           error_map=_err_sq),
    _image("rmse", "RMSE = sqrt(mean((x − r)²)) over all pixels, bins and channels" + _LINEAR,
           error_map=_err_sq, from_mean=np.sqrt, rankable=True, has_surface_variant=True,
           headline=_ALL_RUNS, surface_headline=_ALL_RUNS,
           has_unbiased_variant=True, variance_map=_var_sq, unbiased_definition=(
               "rmse_unbiased = sqrt(max(0, MSE − mean v_r)), v_r the per-pixel variance "
               "of the reference mean: the error against the converged image with the "
               "reference's own noise removed; unknown (an empty cell) where v_r is")),
    _image("relmse", "relMSE = mean((x − r)² / (r² + ε)), ε = 1e-2" + _LINEAR,
           error_map=_err_rel_sq, eps=RELMSE_EPS, rankable=True, has_surface_variant=True,
           headline=_ALL_RUNS,
           has_unbiased_variant=True, variance_map=_var_rel_sq, unbiased_definition=(
               "relmse_unbiased = relMSE − mean(v_r / (r² + ε)): first-order "
               "correction (r is in the denominator; accurate when v_r ≪ r² + ε); unknown "
               "(an empty cell) where v_r is")),
    _image("smape", "SMAPE = mean(|x − r| / (|x| + |r| + ε)), ε = 1e-2, no factor 2" + _LINEAR,
           error_map=_err_smape, eps=SMAPE_EPS, range=(0.0, 1.0), rankable=True,
           has_surface_variant=True),
    _image("rmae", "rMAE = mean(|x − r| / (|r| + 0.01))" + _LINEAR
           + " (noisebase's extra /3 omitted)", error_map=_err_rmae, eps=RMAE_EPS),
    _image("psnr", "PSNR = min(100, 10·log10(1 / mean((T(x) − T(r))²))) dB, data range 1, "
           "100 dB when the MSE is 0; " + TONEMAP_DEFINITION + _ON_SUM,
           higher_is_better=True, domain="ldr", range=(0.0, 100.0), error_map=_err_sq,
           from_mean=_psnr_from_mean, image_fn=psnr_ldr, rankable=True,
           has_surface_variant=True),
    _image("ssim", "SSIM (Wang et al. 2004) on T(x), T(r): Gaussian window σ = 1.5 (11×11), "
           "K1 = 0.01, K2 = 0.03, data range 1, population covariance, per channel then "
           "averaged (skimage structural_similarity); images under 11 px on a side: the same "
           "formula with one window covering the whole image; " + TONEMAP_DEFINITION + _ON_SUM,
           higher_is_better=True, domain="ldr", range=(-1.0, 1.0), per_pixel_map=_ssim_map,
           image_fn=ssim_ldr, rankable=True, has_surface_variant=True, headline=_ALL_RUNS),
    _image("flip", "LDR-FLIP: mean NVIDIA FLIP error (flip_evaluator 1.7, default ppd 67 "
           "(67.02)) between the sRGB images T(x) and T(r); " + TONEMAP_DEFINITION + _ON_SUM,
           domain="ldr", range=(0.0, 1.0), per_pixel_map=_flip_map, image_fn=flip_ldr,
           channels=(1, 3), rankable=True, has_surface_variant=True,
           headline=_STEADY_HEADLINE),
    _image("hdrflip", "HDR-FLIP: mean NVIDIA FLIP error (flip_evaluator 1.7, default ppd 67 "
           "(67.02), ACES tone mapper) on linear values clipped to >= 0; start/stop exposures "
           "chosen by FLIP from the reference once and reused for every image compared with "
           "it (0/0 for a black reference)" + _ON_SUM,
           range=(0.0, 1.0), image_fn=_hdrflip_value, channels=(1, 3)),
    Metric("top1_share", "top1_share = Σ of the largest 1 % of per-pixel squared errors / Σ "
           "of all; near 1: a few pixels decide the MSE", range=(0.0, 1.0),
           variant_of="rmse", variant="share"),
    # the sequence runner's (dbench/run/sequence_run.py, dbench/metrics/video_quality.py)
    Metric("t_rmse", None, kind="temporal", headline=frozenset({"sequence"})),
    Metric("tpsnr", None, higher_is_better=True, domain="ldr", range=(0.0, 100.0),
           kind="temporal", headline=frozenset({"sequence"})),
    Metric("cvvdp", CVVDP_DEFINITION, higher_is_better=True, range=(-math.inf, 10.0),
           kind="video", headline=frozenset({"sequence"})),
)

_SURFACE_TEXT = ("the metric over surface pixels only, pixels whose emitter fraction is 0 "
                 "(lights seen directly or in smooth mirrors excluded; a folder of renders "
                 "without an emitter buffer: the pixels its report lists as surface pixels)")


def _derived(base: Metric, variant: str, definition: str | None,
             headline: frozenset[str]) -> Metric:
    return replace(base, name=f"{base.name}_{variant}", definition=definition,
                   headline=headline, surface_headline=frozenset(), variant_of=base.name,
                   variant=variant, has_surface_variant=False, has_unbiased_variant=False,
                   unbiased_definition=None, image_fn=None)


def _build(records: tuple[Metric, ...]) -> dict[str, Metric]:
    """Every record in report order: the image metrics, their derived forms by
    :data:`VARIANTS`, then the temporal and video metrics."""
    image = [m for m in records if m.kind == "image" and m.variant is None]
    derived = [m for m in records if m.variant is not None]
    derived += [_derived(m, "surface", None, m.surface_headline)
                for m in image if m.has_surface_variant]
    derived += [_derived(m, "unbiased", m.unbiased_definition, frozenset())
                for m in image if m.has_unbiased_variant]
    rest = [m for m in records if m.kind != "image" and m.variant is None]
    ordered = image + [m for v in VARIANTS for m in derived if m.variant == v] + rest
    out = {m.name: m for m in ordered}
    if len(out) != len(ordered):
        raise ValueError("two metric records share a name")
    return out


#: Every metric, base and derived, in report order.
METRICS: dict[str, Metric] = _build(_RECORDS)


def higher_is_better(name: str) -> bool:
    """The direction of ``name`` (unknown names: lower is better)."""
    m = METRICS.get(name)
    return m is not None and m.higher_is_better


def higher_is_better_names() -> frozenset[str]:
    return frozenset(n for n, m in METRICS.items() if m.higher_is_better)


def image_metrics() -> tuple[str, ...]:
    """The metrics :func:`dbench.metrics.compute` knows by name (the image metrics)."""
    return tuple(n for n, m in METRICS.items() if m.kind == "image" and m.variant is None)


def judged() -> tuple[str, ...]:
    """The metrics the judge scores over every pixel and over the surface; every cell has
    them (the default metric list of a run)."""
    return tuple(n for n, m in METRICS.items() if m.has_surface_variant)


def judge_figures() -> tuple[str, ...]:
    """The judge's other figures of its maps: top1_share and the unbiased forms."""
    return tuple(n for n, m in METRICS.items() if m.variant in ("share", "unbiased"))


def sequence_metrics() -> tuple[str, ...]:
    """The temporal and video metrics of sequence cells."""
    return tuple(n for n, m in METRICS.items() if m.kind != "image")


def cell_columns() -> tuple[str, ...]:
    """The metric columns of a cell, in report order: the judged metrics, their surface forms,
    the judge's figures, the sequence metrics."""
    return tuple(n for n, m in METRICS.items()
                 if m.kind != "image" or m.variant is not None or m.has_surface_variant)


def _grouped() -> list[str]:
    """Names with each base metric followed by its derived forms."""
    return [n for b, base in METRICS.items() if base.variant is None
            for n, m in METRICS.items() if n == b or m.variant_of == b]


def rankable() -> tuple[str, ...]:
    """The columns ``--rank-by`` accepts, each metric followed by its forms."""
    return tuple(n for n in _grouped() if METRICS[n].rankable)


def headline(run: str) -> tuple[str, ...]:
    """The metric columns of the headline table of a ``run`` (:data:`RUNS`)."""
    return tuple(n for n in _grouped() if run in METRICS[n].headline)


def surface_definition() -> str:
    names = ", ".join(n for n, m in METRICS.items() if m.variant == "surface")
    return f"`<metric>_surface` ({names}): {_SURFACE_TEXT}"


def definitions(kinds: tuple[str, ...] = KINDS) -> dict[str, str]:
    """{name: the line reports print} of the metrics of ``kinds`` in report order; the surface
    forms share one line, ``surface``."""
    out: dict[str, str] = {}
    for n, m in METRICS.items():
        if m.kind not in kinds:
            continue
        if m.variant == "surface":
            out.setdefault("surface", surface_definition())
        elif m.definition is not None:
            out[n] = m.definition
    return out


#: The line reports print for each metric :func:`dbench.metrics.compute` knows, in order.
DEFINITIONS: dict[str, str] = {n: METRICS[n].definition for n in image_metrics()}
#: Every metric, base or derived, where a larger value is better (others: smaller is better).
HIGHER_IS_BETTER: frozenset[str] = higher_is_better_names()

__all__ = ["Metric", "METRICS", "DEFINITIONS", "HIGHER_IS_BETTER", "KINDS", "RUNS", "VARIANTS",
           "higher_is_better", "higher_is_better_names", "image_metrics", "judged", "judge_figures",
           "sequence_metrics", "cell_columns", "rankable", "headline", "surface_definition",
           "definitions"]
