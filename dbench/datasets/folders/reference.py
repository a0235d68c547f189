"""A folder's reference judged, not trusted: its noise estimated from what the folder holds, and
a warning when it is no better than the noisy input it judges (README.md, "Renders from another
renderer").

The variance of the reference mean, ``reference_var``, comes from the first of these the folder
allows; each says so in ``meta["ref_noise_source"]``:

1. its variance image (``<view>_ref.var.exr``, a ``Variance``/``var`` layer of the reference
   EXR; σ² per sample ÷ ``ref_spp``) or identity statistics (``<view>_ref.stats.npz``: its
   ``var_mean``; statistics of transformed samples are left unused, and said so);
2. its spp (``ref_spp`` in ``dataset.json``, or the highest spp of a series serving as the
   reference) and the noisy series: independent renders of one scene have a variance of the
   mean σ²/spp, so E[(x_s − r)²] = σ²/s + σ²/R and the reference's share of it is s/(R + s);
   per pixel, reference_var ≈ (x_s − r)² · s/(R + s), averaged over the series' spp (the
   reference's error ≈ the noisy error × sqrt(s/R));
3. the convergence of two or more noisy spp: the mean of (x_s − r)² over the image is fitted
   as a/s + b (weighted least squares, each spp's weight its mean's standard error⁻²);
   b is the reference's MSE when it is more than :data:`SIGNIFICANCE` standard errors above 0
   (effective ref spp a/b), and reference_var is each (x_s − r)² scaled to mean b. b also
   takes in any systematic difference between the noisy renders and the reference (another
   renderer setting), which is part of the reference's error as far as the scores go. A b
   resolved below 0 means the series converges to the reference faster than independent
   renders would: the noisy images probably share the reference's samples (progressive
   renders), and the reference's error is unknown;
4. otherwise unknown: no ``reference_var``, ``meta["ref_rmse"]`` NaN (reports say "unknown",
   never 0).

The warning (``meta["reference_warning"]``, one sentence per finding joined by "; ") is given
when the reference

* equals a noisy image of the folder numerically (within half-float rounding,
  :data:`EQUAL_RTOL`): every score would be against that render;
* has no more spp than the noisy input (declared, or as its file name says);
* or has an estimated relMSE, over surface pixels, of at least :data:`RATIO` times the noisy
  input's own (its relMSE against the reference with the reference's share removed): a
  reference with fewer than twice the noisy input's samples' worth.

* or, whatever its estimate says, shows more noise than that estimate allows
  (:func:`noise_ratio`): a reference declared at 4096 spp that is a 4-spp render.

Surface pixels are those that are not directly visible lights (:func:`light_mask`): a light's
absolute error dwarfs everything else, so it hides a noisy reference elsewhere.

**The check that trusts no declaration** (:func:`noise_ratio`). With a high-pass H (a pixel
minus the mean of its four neighbours) the reference R = T + e_R and the noisy input
N = T + e_N (same scene T, independent zero-mean noise) give E⟨HR, H(R − N)⟩ = E‖He_R‖² and
E⟨HN, H(N − R)⟩ = E‖He_N‖²: the scene's own detail cancels, whatever its texture. Their ratio
over surface pixels (away from lights) is the reference's noise variance over the noisy
input's, ≈ spp / ref_spp for independent renders, with a 95 % interval from a bootstrap over
tiles. Where its lower bound is at least :data:`CLAIM_FACTOR` × the ratio the estimate implies
(the reference's estimated relMSE over the noisy input's) and at least :data:`NOISE_FLOOR`, the
reference is flagged as noisier than its estimate says, and the estimate is dropped: the
reference's error is then unknown (no ``reference_var``, ``ref_rmse`` NaN, no unbiased
figures), since a variance the measurement contradicts would make the scores look corrected;
with no estimate, flagged from :data:`RATIO`.
Noise the two share (progressive renders) or a reference smoothed by a denoiser lowers the
ratio, so the check only ever finds too much noise, never proves a reference clean.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ...metrics.params import RELMSE_EPS
from . import exr_layers as xl

#: A reference whose estimated relMSE is at least this share of the noisy input's is flagged.
RATIO = 0.5
#: Standard errors by which the convergence fit's reference MSE must clear 0.
SIGNIFICANCE = 2.0
#: Without an emitter buffer, pixels brighter than LIGHT_FACTOR × the reference's
#: LIGHT_QUANTILE quantile (channel mean) count as lights.
LIGHT_FACTOR = 4.0
LIGHT_QUANTILE = 0.9
#: Albedo at or below this in every channel is black (a light's or the sky's).
BLACK_ALBEDO = 1e-4
#: Relative difference under which two images are numerically equal: half-float rounding
#: (2⁻¹¹ ≈ 4.9e-4) of a copy saved at another precision stays below it.
EQUAL_RTOL = 1e-3
#: A reference whose high-frequency noise (lower 95 % bound) exceeds its estimate's by this
#: factor in variance (it is worth under 1/8 of its declared spp) is flagged...
CLAIM_FACTOR = 8.0
#: ...when that noise is also at least this share of the noisy input's (below it the
#: reference's noise barely weighs on the scores, and bias between the two renders can reach it).
NOISE_FLOOR = 0.05
#: Tiles of the bootstrap: at least this many (fewer: no check), at most about MAX_TILES.
MIN_TILES, MAX_TILES = 8, 256
#: Tile sides: at least MIN_TILE, SMALL_TILE where those give fewer than MIN_TILES tiles.
MIN_TILE, SMALL_TILE = 8, 4
BOOTSTRAP = 2000


def light_mask(reference: np.ndarray, albedo: np.ndarray | None = None,
               emitter: np.ndarray | None = None) -> tuple[np.ndarray, str]:
    """((H, W) bool surface pixels, the rule in words).

    With an emitter buffer: pixels whose emitter fraction is 0 (the judge's surface). Without
    one: pixels no brighter than :data:`LIGHT_FACTOR` × the reference's
    :data:`LIGHT_QUANTILE` quantile, and, with an albedo, not black in albedo where the
    reference is not (an emitter with a black BSDF, or the environment, seen directly).
    """
    r = np.nan_to_num(np.asarray(reference, np.float64)).mean(axis=-1)
    if emitter is not None:
        e = np.asarray(emitter, np.float64).reshape(r.shape)
        return ~(e > 0), "emitter buffer 0"
    q = float(np.quantile(r, LIGHT_QUANTILE))
    light = r > LIGHT_FACTOR * q if q > 0 else np.zeros(r.shape, bool)
    rule = (f"no brighter than {LIGHT_FACTOR:g}× the reference's "
            f"{LIGHT_QUANTILE * 100:g}th percentile")
    if albedo is not None:
        a = np.nan_to_num(np.asarray(albedo, np.float64)).max(axis=-1)
        light |= (a <= BLACK_ALBEDO) & (r > 0)
        rule = "albedo not black where the reference is lit, and " + rule
    return ~light, rule


def _sq(x: np.ndarray, r: np.ndarray) -> np.ndarray:
    """(x − r)² in float64, NaN where x is not finite."""
    d = np.asarray(x, np.float64) - r
    with np.errstate(invalid="ignore", over="ignore"):
        return np.where(np.isfinite(d), d * d, np.nan)


def _filled(v: np.ndarray) -> np.ndarray:
    """Non-finite entries (a noisy pixel that is not finite) get their channel's mean."""
    mean = np.nanmean(v.reshape(-1, v.shape[-1]), axis=0)
    return np.where(np.isfinite(v), v, np.nan_to_num(mean)).astype(np.float32)


def equal(a: np.ndarray, b: np.ndarray) -> bool:
    """Numerically equal images (within :data:`EQUAL_RTOL`)."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return a.shape == b.shape and bool(np.allclose(a, b, rtol=EQUAL_RTOL, atol=1e-7,
                                                   equal_nan=True))


def from_ref_spp(reference: np.ndarray, series: dict[int, np.ndarray], ref_spp: int
                 ) -> np.ndarray:
    """Estimate 2: mean over the series of (x_s − r)² · s/(R + s) (module docstring)."""
    maps = [_sq(x, reference) * (s / (ref_spp + s)) for s, x in series.items()]
    with np.errstate(invalid="ignore"):
        return _filled(np.nanmean(np.stack(maps), axis=0))


def convergence_fit(reference: np.ndarray, series: dict[int, np.ndarray]
                    ) -> tuple[float, float, float]:
    """(a, b, standard error of b) of mean (x_s − r)² = a/s + b (estimate 3)."""
    spps = sorted(series)
    d = [_sq(series[s], reference).mean(axis=-1) for s in spps]
    ok = np.logical_and.reduce([np.isfinite(m) for m in d])
    means = np.array([m[ok].mean() for m in d])
    se = np.array([m[ok].std() / np.sqrt(max(int(ok.sum()), 1)) for m in d])
    se = np.maximum(se, 1e-12 * np.maximum(means, 1e-30))
    x = np.stack([1.0 / np.array(spps, np.float64), np.ones(len(spps))], axis=1)
    wt = 1.0 / se ** 2
    cov = np.linalg.inv(x.T @ (x * wt[:, None]))
    a, b = cov @ (x.T @ (wt * means))
    return float(a), float(b), float(np.sqrt(cov[1, 1]))


def _estimate(reference, series, ref_spp, ref_spp_from, known) -> tuple[Any, str, dict]:
    """(reference_var or None, meta["ref_noise_source"], extra meta)."""
    if known is not None:
        return known[0], known[1], {}
    spps = ", ".join(map(str, sorted(series)))
    if ref_spp:
        return (from_ref_spp(reference, series, ref_spp),
                f"estimated from the noisy series ({spps} spp) and the reference's {ref_spp} "
                f"spp ({ref_spp_from}), assuming variance ∝ 1/spp in independent renders", {})
    if len(series) < 2:
        return (None, "unknown: no variance image or statistics of the reference, no ref_spp "
                      "in dataset.json, and one noisy spp (a convergence estimate needs two)", {})
    a, b, se = convergence_fit(reference, series)
    if b > SIGNIFICANCE * se and a > 0:
        # each image's squared differences scaled to mean b: the per-pixel shape of the
        # noise, the fitted level
        var = np.nanmean(np.stack([_sq(x, reference) * (b / np.nanmean(_sq(x, reference)))
                                   for x in series.values()]), axis=0)
        eff = a / b
        return (_filled(var), f"estimated from the convergence of the noisy series ({spps} "
                f"spp): reference MSE {b:.3g} ± {se:.2g}, worth about {eff:.0f} spp",
                {"ref_spp_effective": float(eff)})
    if b < -SIGNIFICANCE * se:
        return (None, f"unknown: the noisy series ({spps} spp) converges to the reference "
                      "faster than independent renders would (fitted reference MSE "
                      f"{b:.3g} ± {se:.2g}); the noisy images probably share its samples",
                {"nested": True})
    bound = max(b, 0.0) + SIGNIFICANCE * se
    # a bound under one sample says nothing a reader can use ("at least about 0 spp")
    worth = f", worth at least about {a / bound:.0f} spp" if a > 0 and a / bound >= 1 else ""
    return (None, f"unknown: below what the noisy series ({spps} spp) resolves (reference "
                  f"MSE under {bound:.3g}{worth})", {})


def _high_pass(x: np.ndarray) -> np.ndarray:
    """(H − 2, W − 2, C): each interior pixel minus the mean of its four neighbours."""
    return x[1:-1, 1:-1] - 0.25 * (x[:-2, 1:-1] + x[2:, 1:-1] + x[1:-1, :-2] + x[1:-1, 2:])


def noise_ratio(reference: np.ndarray, noisy: np.ndarray, surface: np.ndarray
                ) -> tuple[float, float, float] | None:
    """(ratio, lower, upper 95 % bound) of the reference's noise variance to the noisy input's
    over surface pixels (module docstring), or None where fewer than :data:`MIN_TILES` tiles
    of surface pixels or no noise in the noisy input leave nothing to measure.

    Args:
        reference, noisy: (H, W, C) images of one scene.
        surface: (H, W) bool, pixels that are not lights; a pixel counts where it and its four
            neighbours are surface and every value is finite.
    """
    r = np.asarray(reference, np.float64)
    n = np.asarray(noisy, np.float64)
    hr, hn = _high_pass(r), _high_pass(n)
    with np.errstate(invalid="ignore", over="ignore"):
        pr = (hr * (hr - hn)).sum(axis=-1)
        pn = (hn * (hn - hr)).sum(axis=-1)
    s = surface
    ok = (s[1:-1, 1:-1] & s[:-2, 1:-1] & s[2:, 1:-1] & s[1:-1, :-2] & s[1:-1, 2:]
          & np.isfinite(pr) & np.isfinite(pn))
    pr, pn = np.where(ok, pr, 0.0), np.where(ok, pn, 0.0)
    h, w = pr.shape
    # 8-px tiles, or 4-px ones where 8-px tiles are too few (a 16-px image: 4 tiles of 8, 16
    # of 4; the judge's block bootstrap covers at 4 px, docs/judging.md §3)
    for tile in (max(MIN_TILE, int(np.ceil(np.sqrt(h * w / MAX_TILES)))), SMALL_TILE):
        th, tw = -(-h // tile), -(-w // tile)
        sums = []
        for p in (pr, pn, ok.astype(np.float64)):
            p = np.pad(p, ((0, th * tile - h), (0, tw * tile - w)))
            sums.append(p.reshape(th, tile, tw, tile).sum(axis=(1, 3)).ravel())
        tr, tn, count = sums
        keep = count > 0
        tr, tn = tr[keep], tn[keep]
        if tr.size >= MIN_TILES:
            break
    if tr.size < MIN_TILES or not tn.sum() > 0:
        return None
    pick = np.random.default_rng(0).integers(0, tr.size, (BOOTSTRAP, tr.size))
    with np.errstate(invalid="ignore", divide="ignore"):
        boot = tr[pick].sum(axis=1) / tn[pick].sum(axis=1)
    lo, hi = np.nanquantile(boot, [0.025, 0.975])
    return float(tr.sum() / tn.sum()), float(lo), float(hi)


def _noise_check(ratio: tuple[float, float, float] | None, spp: int, implied: float
                 ) -> str | None:
    """The warning of the high-frequency check, or None. ``implied``: the reference's variance
    over the noisy input's that its estimate gives (NaN: no estimate)."""
    if ratio is None:
        return None
    r, lo, hi = ratio
    measured = (f"its noise over surface pixels is {r:.2g}× the noisy input's (95 % interval "
                f"{lo:.2g}-{hi:.2g}, high-pass comparison), as in a render of about "
                f"{spp / r:.2g} spp")
    if np.isfinite(implied):
        if lo >= max(CLAIM_FACTOR * implied, NOISE_FLOOR):
            return (f"the reference is noisier than its estimate: {measured}, not the "
                    f"{implied:.2g}× that the estimate gives")
        return None
    if lo >= RATIO:
        return f"the reference is not clearly better than the noisy input: {measured}"
    return None


def _surface_mean(m: np.ndarray, surface: np.ndarray) -> float:
    vals = m[surface]
    vals = vals[np.isfinite(vals)]
    return float(vals.mean()) if vals.size else float("nan")


def judge_reference(*, reference: np.ndarray, spp: int, series: dict[int, np.ndarray],
                    names: dict, ref_spp: int | None, ref_spp_from: str,
                    known: tuple[np.ndarray, str] | None = None,
                    albedo: np.ndarray | None = None, emitter: np.ndarray | None = None,
                    surface_from: str = "") -> tuple[np.ndarray | None, dict]:
    """(reference_var or None when unknown, meta entries) for the noisy input at ``spp``.

    Args:
        reference: (H, W, 3) finite reference.
        spp: the noisy input's spp, a key of ``series``.
        series: {spp: (H, W, 3) noisy colour} of every noisy spp of the view (this frame).
        names: {spp: file name, "ref": file name} for the texts.
        ref_spp, ref_spp_from: the reference's spp and where it comes from ("declared in
            dataset.json", "file name"), or None.
        known: (reference_var, how) from the reference's own variance image or statistics.
        albedo, emitter: the buffers :func:`light_mask` uses, or None.
        surface_from: the file the mask's buffer came from, for the text.
    Returns:
        ``reference_var`` float32 (H, W, 3) and ``meta`` keys ``ref_var_known``, ``ref_rmse``
        (NaN when unknown), ``ref_noise_source``, ``ref_relmse_surface``,
        ``noisy_relmse_surface``, ``surface_pixels`` and, when flagged, ``reference_warning``.
    """
    r = np.asarray(reference, np.float64)
    surface, rule = light_mask(r, albedo, emitter)
    warnings = []
    same = [s for s in sorted(series) if equal(series[s], r)]
    rest = {s: x for s, x in series.items() if s not in same}
    if spp in same and known is None:
        var, source, extra = None, "unknown: the reference equals the noisy input", {}
    else:
        if same and not ref_spp:  # it is that render: its spp is known
            ref_spp, ref_spp_from = same[-1], f"equal to {names[same[-1]]}"
        var, source, extra = _estimate(r, rest, ref_spp, ref_spp_from, known)
    for s in same:
        warnings.append(f"the reference {names['ref']} is numerically equal to the noisy "
                        f"input {names[s]} ({s} spp): " + (
                            "every score is against the input itself" if s == spp else
                            f"it is a {s}-spp render"))
    denom = r * r + RELMSE_EPS
    ref_rel = (_surface_mean((np.asarray(var, np.float64) / denom).mean(axis=-1), surface)
               if var is not None else float("nan"))
    measured = _surface_mean((_sq(series[spp], r) / denom).mean(axis=-1), surface)
    own = max(measured - (ref_rel if np.isfinite(ref_rel) else 0.0), 0.0)
    if ref_spp and ref_spp <= spp and spp not in same:
        warnings.append(f"the reference has {ref_spp} spp ({ref_spp_from}), no more than the "
                        f"noisy input's {spp}: it is no better than what it judges")
    elif np.isfinite(ref_rel) and spp not in same and ref_rel >= RATIO * own:
        warnings.append(f"the reference's estimated relMSE over surface pixels ({ref_rel:.3g}) "
                        f"is not clearly below the noisy input's ({own:.3g}; flagged from "
                        f"{RATIO:g}× it): its own error weighs on every score")
    elif spp not in same:
        ratio = noise_ratio(r, series[spp], surface)
        implied = ref_rel / own if np.isfinite(ref_rel) and own > 0 else float("nan")
        found = _noise_check(ratio, spp, implied)
        if found:
            warnings.append(found)
            if np.isfinite(implied):
                # the measurement contradicts the estimate: it would misstate the reference's
                # error and make the unbiased figures look corrected, so the error is unknown
                var, ref_rel = None, float("nan")
                source = f"unknown: the high-pass check contradicts the estimate ({source})"
        elif ratio is None:  # an estimate nothing measured is not stated as a fact
            source += ("; not checked against the noisy input (too few surface pixels for "
                       "the high-pass comparison)")
    if extra.pop("nested", False):
        warnings.append(source.removeprefix("unknown: "))
    n_surface = int(surface.sum())
    where = f" ({surface_from})" if surface_from else ""
    meta = {"ref_var_known": var is not None,
            "ref_rmse": (float(np.sqrt(max(float(np.mean(var, dtype=np.float64)), 0.0)))
                         if var is not None else float("nan")),
            "ref_noise_source": source, "ref_relmse_surface": ref_rel,
            "noisy_relmse_surface": own if np.isfinite(measured) else float("nan"),
            "surface_pixels": f"{n_surface} of {surface.size}: {rule}{where}", **extra}
    if warnings:
        meta["reference_warning"] = "; ".join(warnings)
    return var, meta


def known_variance(ref: dict, ref_spp: int | None, read: Any, files: dict,
                   shape: tuple[int, ...]) -> tuple[np.ndarray, str] | None:
    """Estimate 1: (variance of the reference mean, how) from the reference's variance image
    (σ² per sample ÷ ``ref_spp``) or identity statistics, else None."""
    from .export import check_variance, read_stats_npz

    if "variance" in ref and ref_spp:
        sigma2 = check_variance(read(ref["variance"]).astype(np.float64),
                                str(ref["variance"].file))
        files["reference_var"] = ref["variance"].file.name
        return ((sigma2 / ref_spp).astype(np.float32),
                f"variance image {ref['variance'].file.name} ÷ {ref_spp} spp")
    if "stats" in ref:
        stats = read_stats_npz(ref["stats"], shape, spp=ref_spp)
        if stats.transform == "identity":  # var_mean of untransformed samples is the answer
            files["reference_var"] = ref["stats"].name
            return stats.var_mean.astype(np.float32), f"statistics {ref['stats'].name}"
    return None


def folder_reference(info: Any, frame: int | None, spp: int, read: Any, files: dict,
                     reference: np.ndarray, buffers: dict
                     ) -> tuple[np.ndarray | None, dict, np.ndarray | None]:
    """:func:`judge_reference` for one noisy spp of a scanned folder (a
    :class:`~dbench.datasets.folders.load.FolderInfo`); ``read`` reads a layer, ``files`` records
    the reference variance's file, ``buffers`` the frame's loaded buffers (its emitter is
    used when there; else the folder's albedo is read for the surface mask). The third value:
    without an emitter buffer, the (H, W, 1) lights of that mask (:func:`light_mask`), which
    the judge's surface metrics then leave out (``Frame.judged_lights``), so they are over the
    pixels the report lists as surface; else None."""
    plan = info._plan
    ref = plan[(frame, "ref")]
    slots = {s: plan[(frame, s)] for s in info.spps}
    known = known_variance(ref, info.ref_spp, read, files, reference.shape)
    known_note = unused = ""
    if known is None and "variance" in ref:
        # σ² per sample needs the sample count to give the variance of the mean
        known_note = f" ({ref['variance'].file.name} holds σ² per sample, but ref_spp is unknown)"
    if known is None and "stats" in ref and info.reference_from == "file":
        from .export import read_stats_npz

        # the variance of transformed samples' mean is not the colour's: the file is left
        # unused, and said so whatever gives the variance instead
        unused = (f" ({ref['stats'].name} holds statistics of "
                  f"{read_stats_npz(ref['stats'], settings_only=True)[0]}-transformed "
                  "samples, not the colour's variance: unused)")
    emitter, albedo, surface_from = buffers.get("emitter"), None, ""
    if emitter is not None:
        surface_from = files.get("emitter", "")
    elif "albedo" in info.buffers:
        layer = slots[spp].get("albedo") or ref["albedo"]
        albedo, surface_from = read(layer), layer.file.name
    # every spp's colour feeds the estimate: a NaN in another spp's file is refused as the
    # loaded spp's would be, not dropped from the estimate unsaid
    series = {s: xl.refuse_non_finite(read(slot["color"]), slot["color"].file, "colour")
              for s, slot in slots.items()}
    names = {s: slot["color"].file.name for s, slot in slots.items()}
    names["ref"] = ref["color"].file.name
    var, meta = judge_reference(
        reference=reference, spp=spp, series=series,
        names=names, ref_spp=info.ref_spp,
        ref_spp_from=("declared in dataset.json" if info.reference_from == "file" else
                      "the highest spp of the series, from its file name"),
        known=known, albedo=albedo, emitter=emitter, surface_from=surface_from)
    if known_note and not meta["ref_var_known"]:
        meta["ref_noise_source"] += known_note
    meta["ref_noise_source"] += unused
    lights = None
    if emitter is None:
        lights = (~light_mask(np.asarray(reference, np.float64), albedo)[0])[..., None]
    return var, meta, None if lights is None else lights.astype(np.float32)
