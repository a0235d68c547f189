"""Constants of ``svgf`` / ``asvgf`` with their sources (docs/methods/svgf.md; [dbench] marks values
chosen here, [Falcor] values taken from Falcor's SVGF pass), and the named presets."""
from __future__ import annotations

import numpy as np

#: B3-spline taps h1 (docs/methods/svgf.md §5).
H1 = np.array([1 / 16, 1 / 4, 3 / 8, 1 / 4, 1 / 16])
#: 3×3 Gaussian (1,2,1)ᵀ(1,2,1)/16 that blurs the variance before each iteration (docs/methods/svgf.md §3).
G3 = np.array([0.25, 0.5, 0.25])
EPS_Z = 1e-6       # [dbench]
EPS_VAR = 1e-4     # [Falcor varianceEpsilon]
#: [dbench] a_eff = clip(albedo, ALBEDO_FLOOR, 1) per channel, in place of docs/methods/svgf.md §2's "the
#: albedo where > 1e-3, else 1". The spec's switch jumps from a_eff = 1 (albedo 0: a
#: conductor's AOV) to a_eff = 0.001 (albedo just above it: a dark reflection's PSR albedo),
#: so neighbouring pixels and frames carried illumination up to 1000x apart, the filters mixed
#: them, and on one of the autoencoder's training sequences SVGF's RMSE over surfaces was 52x
#: plain accumulation's. The floor keeps a_eff continuous and bounds the amplification at 5x.
#: 0.2 is the smallest floor of {0.02, 0.05, 0.1, 0.2, 0.3, 0.5, 1} within 5 % of the best
#: geometric-mean relMSE of SVGF and A-SVGF on 8 of those training sequences (disjoint from
#: the catalogue; docs/temporal.md §12); 1 means no demodulation.
ALBEDO_FLOOR = 0.2
N_SPATIAL = 4      # history below this: spatial variance (docs/methods/svgf.md §4)
SPATIAL_RADIUS = 3  # 7×7 window

#: ``dbench`` (the default) keeps the paper's weights and α but filters with the variance of
#: the accumulated colour (``variance_of="mean"``), feeds the unfiltered accumulation back
#: (``feedback_tap=None``) and scales the à-trous footprint with the image (``iterations="auto"``,
#: :func:`auto_iterations`); docs/temporal.md §3 gives the reasons, results/temporal.md the
#: study.
#: ``paper`` is the SVGF paper [SVGF], ``falcor`` Falcor's SVGFPass defaults [Falcor].
#: ``variance_boost`` (docs/temporal.md §15; the papers do not mention either form):
#: "svgf" multiplies the spatial variance of a history of N < 4 frames by 4/N, as Falcor's
#: SVGFFilterMoments pass does ("give the variance a boost for the first frames"); "asvgf"
#: multiplies the standard deviation of every pixel's estimate by max(1, 8/N), as Schied's A-SVGF
#: code does (q2vkpt's asvgf_temporal.comp), N being A-SVGF's history N' after its gradient;
#: "gradient" [dbench] the latter where A-SVGF's gradient shortened the history, the former on
#: new surfaces (docs/temporal.md §18; :mod:`.boost`); False none. ``svgf`` takes "svgf" (on
#: the training sequences outside the catalogue its relMSE ratio 0.479 → 0.478 over 4 seeds,
#: "asvgf" 0.480), ``asvgf`` takes "gradient" with Schied's Gaussian luminance weight
#: (``ASVGF.preset_overrides``).
PRESETS = {
    "dbench": dict(sigma_z=1.0, sigma_n=128.0, sigma_l=4.0, iterations="auto", feedback_tap=None,
                   alpha_min=0.2, alpha_min_moments=0.2, variance_of="mean",
                   luminance_kernel="gaussian", variance_boost="svgf"),
    "paper": dict(sigma_z=1.0, sigma_n=128.0, sigma_l=4.0, iterations=5, feedback_tap=0,
                  alpha_min=0.2, alpha_min_moments=0.2, variance_of="sample",
                  luminance_kernel="laplacian", variance_boost=False),
    "falcor": dict(sigma_z=1.0, sigma_n=128.0, sigma_l=10.0, iterations=4, feedback_tap=1,
                   alpha_min=0.05, alpha_min_moments=0.2, variance_of="sample",
                   luminance_kernel="laplacian", variance_boost="svgf"),
}
VARIANCE_OF = ("mean", "sample")
#: ``variance_boost``: none, Falcor's SVGF pass, Schied's A-SVGF code, or each of those two
#: where it applies ("gradient", above); True is "svgf".
VARIANCE_BOOSTS = (False, "svgf", "asvgf", "gradient")
#: The luminance edge-stopping weight w_l = exp(−d) with d = |l_p − l_q| / (σ_l √(g(Var)) + ε):
#: "laplacian" as the SVGF paper and Falcor write it, "gaussian" exp(−d²) as Schied's A-SVGF
#: code does. [dbench] "gaussian" in the ``dbench`` preset: on 8 training sequences outside the
#: catalogue it lowered SVGF's geometric-mean relMSE ÷ accumulation from 0.472 to 0.453 (RMSE
#: 0.913 → 0.910) with the paper's σ_l = 4 kept, the best of σ_l ∈ {2, 4, 6, 8}; A-SVGF keeps
#: the Laplacian there until it took its own code's variance boost (its relMSE rose, 0.542 →
#: 0.594, and with Falcor's boost 0.525 → 0.543 over 4 seeds; with the "asvgf" boost it fell,
#: 0.491 → 0.473; docs/temporal.md §13, §15).
LUM_KERNELS = ("gaussian", "laplacian")
MAX_ITERATIONS = 12


def auto_iterations(height: int, width: int) -> int:
    """À-trous iterations K for ``iterations="auto"`` [dbench]: the paper's K = 5 (footprint
    ±62 px) from 256 px up, one fewer per halving of the shorter side below it, at least 1:
    32 px → 2, 64 px → 3, 128 px → 4. The footprint 2^(K+1) − 2 stays about a quarter of the
    shorter side, as 5 iterations are on the 256-px images; at 64 px the paper's ±62 px spans
    the whole image and blurs the illumination across it (results/temporal.md)."""
    side = max(1, min(int(height), int(width)))
    return int(min(5, max(1, int(np.floor(np.log2(side))) - 3)))
#: A-SVGF's temporal gradient (docs/methods/svgf.md §6; docs/temporal.md §14): "seed"
#: G = filter((δ/Δ)²) per stratum as the seed writes it (the default); "filtered"
#: G = (|filter(δ)| / filter(Δ))², the paper's ratio of the separately filtered δ and Δ squared
#: as the seed's G; "paper" λ = |filter(δ)| / filter(Δ) with the paper's α = mix(α0, 1, λ);
#: "filtered_abs" G = (filter(|δ|) / filter(Δ))², the magnitudes filtered, so that per-sample
#: changes of either sign (two lights trading places) do not cancel
GRADIENT_MODES = ("seed", "filtered", "paper", "filtered_abs")
ALPHA0_PAPER = 0.2
