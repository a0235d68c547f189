"""``NAME+gate``: any steady method followed by ProDen's t-test gate (docs/methods/statistical.md §12).

The gate mixes the method's output back towards the noisy mean wherever the two differ by many
standard errors of that mean, using dbench's exact per-pixel variance of the mean
(:func:`~dbench.methods.kernels.variance_floor.linear_variance` of ``Frame.stats``). As the variance of
the mean falls with spp, every pixel the method got wrong is handed back to the input, so the
output converges to the noisy input's limit: a consistent variant of a biased method.

``gated_class(base)`` builds the wrapper class of a registered steady method (built-in or
plugin); :func:`dbench.registry.method_class` calls it for any name ending in ``+gate``, so the
variants are never listed one by one. The wrapper:

* works where its method works on steady frames (and frame by frame on sequences);
* needs what the method needs plus ``stats``, and passes its optional needs on;
* takes the method's parameters plus ``gate_alpha`` (α of docs/methods/statistical.md §12, in [0, 1], default 1),
  ``gate_k`` (2.0) and ``gate_t0`` (4.2); ``gate_alpha = 0`` returns the input;
* pixels whose noisy colour is not finite keep the method's output (there is nothing to mix
  back to), and so do pixels with fewer than 2 samples (their variance of the mean is unknown,
  so nothing is significant: at 1 spp ``NAME+gate`` equals ``NAME``);
* [dbench] with ``gate_emitters`` (default True) and a frame that has the optional ``emitter``
  buffer, pixels covered by a light (seen directly or in a smooth mirror) keep the input in
  proportion to their coverage after the gate
  (:func:`~dbench.methods.kernels.emitters.keep_emitters`, the rule of ``nca`` and
  ``autoencoder``): a lamp's edge pixels carry coverage noise with a large variance
  of the mean, so the t-test rarely rejects a filter's blur there, and on ``cornell`` at 256²,
  1024 spp those 108 pixels held 89 % of ``oidn+gate``'s squared error (RMSE over all pixels
  1.63x the noisy input's; 0.97x with the rule). ``gate_emitters=False`` is the gate of
  docs/methods/statistical.md §12 alone. A method that applies the rule itself (``keeps_emitters``: ``nca``,
  ``autoencoder``) is not given it twice: a second pass would hand a lamp's edge pixel of
  coverage e back by 1 − (1 − e)² instead of e;
* [dbench] with ``gate_pool`` r (default 5, the gate's 11×11 footprint; 0 for docs/methods/statistical.md §12
  alone) the per-pixel variance of the mean is floored at its mean over the (2r + 1)² window
  (:mod:`~dbench.methods.kernels.variance_floor`): at a few spp a pixel's own variance
  estimate is noisy and, for heavy-tailed radiance, low exactly where rare bright samples were
  missed, so the test handed good pixels back to the noise (``oidn+gate`` on ``fireflies``,
  256², 16 spp: relMSE 2.2x plain OIDN's, 1.07x with the floor; results/learned.md);
* [dbench] with ``gate_handback="wiener"`` (the default; ``"pixel"`` for docs/methods/statistical.md §12) the gate
  hands back the local mean of the residual where the t-test fails, and the rest of it only in
  proportion to how far its window energy exceeds the noise's
  (:mod:`~dbench.methods.kernels.handback`): the spec's gate hands back the pixel's whole
  residual, noise included, which made ``oidn+gate`` 2-10x plain OIDN's relMSE at 64-256 spp
  on ``fireflies`` and ``caustic`` (results/learned.md). ``gate_pool=0, gate_handback="pixel"``
  is the gate of docs/methods/statistical.md §12;
* runs the compiled gate (:func:`~dbench.methods.kernels.gate.proden_gate_stats`, the passes
  of :func:`~dbench.methods.kernels.gate.proden_gate_fast` fed from the statistics);
  ``gate_backend="reference"`` runs the readable SciPy form.

Example:
    >>> from dbench.registry import get
    >>> m = get("jbf+gate", gate_alpha=0.5)
    >>> sorted(m.needs)
    ['albedo', 'color', 'normal', 'stats']
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from ...denoiser import GATE_SUFFIX, Denoiser
from ...errors import DbenchInputError
from ..checks import check_choice
from ..kernels.emitters import keep_emitters
from ..kernels.gate import proden_gate_stats
from ..kernels.gate_reference import GATE_K, GATE_T0, proden_gate
from ..kernels.variance_floor import linear_variance
from ..kernels.handback import HANDBACKS
from ..kernels.variance_floor import POOL_RADIUS

SUFFIX = GATE_SUFFIX
GATE_DEFAULTS: dict[str, Any] = dict(gate_alpha=1.0, gate_k=GATE_K, gate_t0=GATE_T0,
                                     gate_backend="fast", gate_emitters=True,
                                     gate_pool=POOL_RADIUS, gate_handback="wiener")
GATE_BACKENDS = ("fast", "reference")

_CLASSES: dict[type, type] = {}


def _check_number(name: str, value: Any, lo: float, hi: float) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        v = math.nan
    if isinstance(value, bool) or not (lo <= v <= hi):
        raise DbenchInputError(f"{name}: expected a number in [{lo}, {hi}], got {value!r}")
    return v


def _require_stats(stats: Any) -> Any:
    if stats is None:
        raise DbenchInputError("stats: missing; expected SampleStats of shape (H, W, 3): the "
                               "ProDen gate needs the per-pixel variance of the noisy mean")
    return stats


def gate_output(color: np.ndarray, denoised: np.ndarray, stats: Any, *, alpha: float = 1.0,
                k: float = GATE_K, t0: float = GATE_T0, backend: str = "fast",
                pool: int = 0, handback: str = "pixel") -> np.ndarray:
    """The gate applied to one image: (H, W, 3) noisy colour, (H, W, 3) method output and the
    frame's statistics -> (H, W, 3) float32. Non-finite noisy pixels keep the output; ``pool``
    r > 0 floors the variance over (2r + 1)² windows first; ``handback`` is the rule of what
    goes back (:mod:`~dbench.methods.kernels.handback`)."""
    _require_stats(stats)
    # [dbench] Fewer than 2 samples: the variance of the mean is unknown (SampleStats stores 0
    # there), not zero, so there is no evidence against the method's value: the gate stays
    # open (α). Read as a known zero it would return the noisy input at 1 spp.
    counts = np.asarray(stats.n)
    # Above 1 spp the compiled passes report the rows whose variance has a value ≤ 0 or NaN,
    # and the counts are read only there (elsewhere every n ≥ 2: a 22 MB read less at 720p);
    # otherwise they are read first, so that at 1 spp the blurs can be skipped.
    scan_rows = (backend != "reference" and counts.ndim == 3 and counts.size > 0
                 and counts.shape[0] == np.shape(color)[0] and counts.flat[0] >= 2)
    if not scan_rows:
        any_unknown = counts.size > 0 and bool(counts.min() < 2)  # no (H, W, 3) mask if none
        unknown = counts < 2 if any_unknown else None
        if any_unknown and np.all(unknown):  # 1 spp: nothing to test, skip the blurs
            return _open_gate(color, denoised, alpha)[0]
    open_gate = None
    if backend == "reference":
        open_gate, hdr, den = _open_gate(color, denoised, alpha)
        out = proden_gate(hdr, den, linear_variance(stats, color), alpha=alpha, k=k,
                          t0=t0, pool_radius=pool, handback=handback).astype(np.float32)
    else:  # the same substitutions and the linear variance, inside the compiled passes
        positive = np.empty(counts.shape[0], np.bool_) if scan_rows else None
        out = proden_gate_stats(color, denoised, stats, alpha=alpha, k=k, t0=t0,
                                pool_radius=pool, handback=handback, rows_positive=positive)
        if scan_rows:
            rows = np.flatnonzero(~positive)
            any_unknown = rows.size > 0 and bool(counts[rows].min() < 2)
            unknown = counts < 2 if any_unknown else None
    if not any_unknown:
        return out
    if open_gate is None:
        open_gate = _open_gate(color, denoised, alpha)[0]
    return np.where(unknown, open_gate, out)


def _open_gate(color: np.ndarray, denoised: np.ndarray, alpha: float):
    """(hdr + α (den − hdr) as float32, hdr, den): the open gate's output, with non-finite
    noisy values replaced by the method's and non-finite method values by the noisy ones."""
    hdr = np.where(np.isfinite(color), color, denoised)
    den = np.where(np.isfinite(denoised), denoised, hdr)
    return (hdr + alpha * (den - hdr)).astype(np.float32), hdr, den


def gated_class(base: type[Denoiser]) -> type[Denoiser]:
    """The ``NAME+gate`` class of the steady method class ``base`` (made once, then reused).

    Raises DbenchInputError when ``base`` cannot carry the gate: it does not run on steady
    frames, or it is already gated."""
    if base in _CLASSES:
        return _CLASSES[base]
    name = f"{base.name}{SUFFIX}"
    if getattr(base, "wrapped", None) is not None:
        raise DbenchInputError(f"{name}: {base.name} is already gated")
    if "steady" not in base.kinds:
        raise DbenchInputError(f"{name}: the gate wraps methods that run on steady frames; "
                               f"{base.name} works on {sorted(base.kinds)}")
    clash = set(GATE_DEFAULTS) & set(base.defaults)
    if clash:
        raise DbenchInputError(f"{name}: {base.name} has parameters named like the gate's "
                               f"({sorted(clash)})")

    class Gated(Denoiser):
        __doc__ = (f"``{base.name}`` followed by ProDen's t-test gate (docs/methods/statistical.md "
                   f"§12; :mod:`dbench.methods.gate`).")
        wrapped = base
        kinds = {"steady"}
        needs = set(base.needs) | {"stats"}
        optional_needs = (set(base.optional_needs) | {"emitter"}) - {"stats"}
        defaults = {**base.defaults, **GATE_DEFAULTS}

        def __init__(self, **params: Any) -> None:
            super().__init__(**params)
            p = self.params
            _check_number("gate_alpha", p["gate_alpha"], 0.0, 1.0)
            _check_number("gate_k", p["gate_k"], 1e-3, 1e3)
            _check_number("gate_t0", p["gate_t0"], 0.0, 1e3)
            check_choice("gate_backend", p["gate_backend"], GATE_BACKENDS)
            check_choice("gate_handback", p["gate_handback"], HANDBACKS)
            pool = p["gate_pool"]
            if isinstance(pool, bool) or not isinstance(pool, (int, np.integer)) \
                    or not 0 <= pool <= 64:
                raise DbenchInputError(f"gate_pool: expected an integer in [0, 64], got {pool!r}")
            if not isinstance(p["gate_emitters"], bool):
                raise DbenchInputError(f"gate_emitters: expected True or False, "
                                       f"got {p['gate_emitters']!r}")
            self.inner = base(**{k: v for k, v in p.items() if k not in GATE_DEFAULTS})
            # the method's needs follow its parameters (oidn with features=none: colour)
            self.needs = set(self.inner.needs) | {"stats"}
            self.last_settings: dict[str, Any] = {}

        def reset(self) -> None:
            self.inner.reset()

        def denoise(self, data: Any) -> np.ndarray:
            if getattr(data, "kind", "steady") != "steady":
                raise DbenchInputError(f"{self.name}: expected a steady Frame, got "
                                       f"{getattr(data, 'kind', type(data).__name__)} data")
            stats = _require_stats(getattr(data, "stats", None))  # before the method runs
            out = self.inner.denoise(data)
            # the harness checks the gated output only: the method's own must be checked here,
            # or a wrong one fails inside the gate ("cannot reshape array of size 1 ...")
            if out is None or np.shape(out) != np.shape(data.color):
                raise DbenchInputError(f"{base.name} output: expected shape "
                                       f"{np.shape(data.color)}, got "
                                       f"{'None' if out is None else np.shape(out)}")
            p = self.params
            gated = gate_output(data.color, out, stats, alpha=float(p["gate_alpha"]),
                                k=float(p["gate_k"]), t0=float(p["gate_t0"]),
                                backend=p["gate_backend"], pool=int(p["gate_pool"]),
                                handback=p["gate_handback"])
            if p["gate_emitters"] and not base.keeps_emitters:
                gated = keep_emitters(data.color, gated, getattr(data, "emitter", None))
            self.last_settings = {**getattr(self.inner, "last_settings", {}),
                                  "gate_alpha": float(p["gate_alpha"]),
                                  "gate_transform": getattr(stats, "transform", "identity")}
            return gated

    Gated.__name__ = Gated.__qualname__ = f"{base.__name__}Gated"
    Gated.name = name
    _CLASSES[base] = Gated
    return Gated


__all__ = ["GATE_DEFAULTS", "SUFFIX", "gate_output", "gated_class"]
