"""Transient (time-resolved) datasets through mitransient (docs/transient.md, docs/mitsuba.md).

Scenes of kind ``transient``: ``cornell-transient`` and ``caustic-transient`` (``transient_path``)
and ``fog-transient`` (a homogeneous medium, ``transient_prbvolpath``; the setting of seed 004);
``cloud-transient``, ``fog-unwarped`` and the scene parameters (medium, emission pulse or step,
scattering orders) are in :mod:`dbench.datasets.transient.media`. The time axis is optical path
length (OPL) in metres, warped (the camera segment is included, as a real ultrafast sensor
records it); each scene carries a window
[``start_opl``, ``end_opl``) chosen with :func:`size_window` from the scene geometry (earliest
direct arrival) and a pilot render (the OPL below which ``coverage`` of the steady energy
arrives). ``bins`` splits the window; ``bin_width_opl = (end − start)/bins``.

Collectors of the per-bin statistics (docs/methods/statistical.md §11):

* (a) :func:`collect_passes` (:mod:`dbench.datasets.transient.passes`): 1-spp passes with a
  box filter; the film histogram of a pass holds, per pixel and bin, exactly the sum of that
  pixel's one path contributions in the bin, which is one sample; it is transformed and added to float64 power sums on the host
  (:class:`~dbench.datasets.stats.PowerSums`, bins a path never reaches add g(0) − K = 0).
  Several samples per call come from a Mitsuba ``batch`` sensor holding copies of the camera
  (the transient film works as the batch film; each copy is an independent sample).
* (b) :func:`collect_in_integrator`: the in-integrator collectors (running sums per path,
  flushed with atomics), whose memory does not depend on spp:
  :mod:`dbench.datasets.transient.collector` in ``transient_path`` and
  :mod:`dbench.datasets.transient.collector_media` in ``transient_prbvolpath`` (media).

Buffers of a :class:`~dbench.data.TransientFrame` from :func:`load_transient`: ``color``
(H, W, T, 3), ``stats`` and ``non_zero`` (H, W, T, 3), ``steady`` (H, W, 3; the same samples,
whole path length), ``albedo``, ``normal``, ``depth``, ``position`` (H, W, ·; steady AOV render of
the same camera; for the fog scene, of the surfaces behind the fog), ``emitter`` (H, W, 1; the
fraction of the footprint whose primary ray sees a light, from the same feature render, fog
ignored), ``reference`` (H, W, T, 3, plain transient render at ref_spp ≥ 16·spp, same window,
seed ``ref_seed``, in K ≥ 16 chunks) and ``reference_var`` (H, W, T, 3, the variance of the
reference mean per bin from the chunk spread, docs/judging.md §2). ``meta`` holds the window
(``start_opl``, ``bin_width_opl``, ``bins``, ``end_opl``, ``units``), ``energy_fraction``
(Σ color / Σ steady: the share of the steady energy inside the window; a step's last bin over
Σ steady), ``emitter`` (pulse or step), ``scene_params`` (the ``--scene-param`` values, empty
for a catalogue scene as it is), integrator settings and timings, and ``nonfinite_samples``
and ``ref_nonfinite_samples``: the noisy video's and the reference's NaN or ±Inf sample values
over all bins, counted as 0 (collector (b) counts them per path and bin; (a) and the
reference as their renders hold them, :func:`collect_passes`: (a) once per path in its steady
image, which :func:`~dbench.datasets.nonfinite.nonfinite_text` says), with
``nonfinite_warning`` where either is above 0 (:mod:`dbench.datasets.nonfinite`).

Example:
    >>> from dbench import datasets
    >>> v = datasets.load("cornell-transient", spp=8, res=16, bins=40)   # doctest: +SKIP
    >>> v.color.shape, v.meta["energy_fraction"] > 0.9                   # doctest: +SKIP
    ((16, 16, 40, 3), True)
"""
from __future__ import annotations

import time
from typing import Any, Callable, Iterable

import numpy as np

from ...data import SampleStats, TransientFrame, check_count, check_transform
from ...errors import DbenchInputError
from ...resolution import parse_res
from .. import render as _render
from ..scenes import catalogue as _scenes
from ..cache import Cache
from ..mitsuba_env import mitsuba, scene_cache, versions
from ..nonfinite import NONFINITE_VERSION, note_nonfinite, zeroed
from ..references import check_ref_seed, check_render_args, reference_meta
from ..references import reference_spp as default_ref
from ..scenes.record import Scene, register_scene
from .media import (EMISSION, FOG, FOG_PARAMS, FOG_RANGE_WINDOW, _fog_room, media_variant,
                    transient_variant)
from ..stats import ZERO_VARIANCE_RTOL
from .render import (DEFAULT_REFERENCE_CHUNK, _mitransient, batch_copies, loaded_transient,
                     render_plain, render_reference)
from .passes import TransientRender, collect_passes, energy_fraction, pass_samples
from .scene import (SPEED_OF_LIGHT, TRANSIENT_BUFFERS, TransientScene, Window, check_bins,
                    transient_film)
from .window import direct_arrival_dict, direct_arrivals, expected_direct_bins, size_window

COLLECTORS = ("auto", "a", "b")
DEFAULT_TRANSFORM = "identity"   # docs/methods/statistical.md §3: transient default
#: Version of the ``total_var`` array stored with the statistics (the noisy total's variance).
TOTAL_VAR_VERSION = 2

#: Σ color ≥ this share of Σ steady counts as a window covering all contributions (docs/transient.md §6).
COVERS_ALL = 0.999


# ---------------------------------------------------------------------------------------------
# the catalogue


def _register(name: str, description: str, **kw: Any):
    def wrap(build: Callable[[Any, int], dict]) -> Callable[[Any, int], dict]:
        register_scene(TransientScene(name=name, kind="transient", description=description,
                                      build=build, provides=TRANSIENT_BUFFERS, **kw))
        return build
    return wrap


# Windows from size_window(scene, coverage=0.99, res=24, spp=256): start = first direct arrival
# rounded down (no energy before it in the pilot), end = 99 % of the steady energy, rounded up
# to 0.5 m (results/transient.md lists the measured fractions).
@_register("cornell-transient", "Cornell box, time-resolved (transient_path, warped OPL)",
           max_depth=8, window_start=3.8, window_end=11.5, default_bins=200,
           declared=(EMISSION,), variant=transient_variant)
def cornell_transient(mi, res) -> dict:
    return _scenes.cornell(mi, res)


@_register("caustic-transient", "glass sphere caustic, time-resolved: the caustic arrives late "
           "(glass OPL)", max_depth=12, window_start=3.7, window_end=14.0,
           default_bins=200, declared=(EMISSION,), variant=transient_variant)
def caustic_transient(mi, res) -> dict:
    return _scenes.caustic(mi, res)


@_register("fog-transient", "Cornell-style room filled with homogeneous fog (σs 0.6, σa 0.1 /m, "
           "HG g 0.3): transient_prbvolpath", max_depth=8, window_start=3.8, window_end=10.0,
           default_bins=200, integrator="transient_prbvolpath", steady_integrator="volpath",
           feature_build=lambda mi, res: _fog_room(mi, res, with_fog=False), medium=FOG,
           declared=FOG_PARAMS, variant=media_variant(_fog_room, FOG_RANGE_WINDOW))
def fog_transient(mi, res) -> dict:
    return _fog_room(mi, res, with_fog=True)


# ---------------------------------------------------------------------------------------------
# collector (b): in the integrator


def collect_in_integrator(scene: TransientScene, res, spp: int, seed: int = 0,
                          bins: int | None = None, transform: str = DEFAULT_TRANSFORM,
                          lam: float = 0.5, per_pass: bool = False, slots: int = 0,
                          rows: bool = True, stats: bool = True) -> TransientRender:
    """Collector (b): running per-path sums inside the scene's integrator, flushed into float64
    power sums with atomics (docs/methods/statistical.md §11.2 mode B; ``transient_path``:
    :mod:`dbench.datasets.transient.collector`, ``transient_prbvolpath``:
    :mod:`dbench.datasets.transient.collector_media`).

    Args:
        per_pass: render ``spp`` 1-spp passes with collector (a)'s seeds (bit-identical to (a)
            with ``copies=1``); default: one call of ``spp`` samples (seed
            ``pass_seed("transient-b", seed, 0)``).
        slots: per-path slots (0 = 2·max_depth, exact).
        rows: find the rows the cache stores and gather them (``TransientRender.rows``, ``kept``).
        stats: compute the moments (without: colour only; ``stats``, ``non_zero``, ``sums`` None).
    """
    if scene.integrator not in IN_INTEGRATOR:
        raise DbenchInputError(f"collector: (b) runs inside {' or '.join(IN_INTEGRATOR)}; "
                               f"scene {scene.name} uses {scene.integrator}, use collector 'a'")
    if scene.needs_passes:  # its signal is made from whole rendered passes
        raise DbenchInputError(f"collector: (b) sums inside one render; scene {scene.name} "
                               f"needs whole passes (step emission or a minus scene), use 'a'")
    check_count("spp", spp)
    check_transform(transform, lam)
    _mitransient()
    window = scene.window(bins)
    sc = loaded_transient(scene, res, window, 1)
    col = _collector(sc, scene.integrator, transform, float(lam), scene.max_depth,
                     scene.rr_depth, scene.camera_unwarp, int(slots))
    col.reset()
    if per_pass:
        for k in range(spp):
            col.render(1, _render.pass_seed("transient", seed, k))
    else:
        col.render(spp, _render.pass_seed("transient-b", seed, 0))
    t0 = time.perf_counter()
    sums = col.power_sums(unpack=False) if stats else None
    mom = col.moments(ZERO_VARIANCE_RTOL, rows=rows, stats=stats)
    stats = SampleStats(n=float(col.n), mean=mom["mean"], var_mean=mom["var_mean"],
                        m3=mom["m3"], transform=transform, lam=float(lam),
                        diagnostics=col.diagnostics()) if stats else None
    color, non_zero = mom["color"], mom.get("non_zero")
    steady = (col.steady / col.n).astype(np.float32)
    total_var = col.total_var()
    state_bytes, diagnostics = col.nbytes(), col.diagnostics()
    layout = col.state.layout
    col.release()  # the cached collector keeps its integrator, not the sums
    return TransientRender(color=color, steady=steady, stats=stats, non_zero=non_zero,
                           total_var=total_var, rows={"stats": mom.get("rows"),
                                                      "color": mom.get("color_rows")},
                           kept={"stats": mom.get("kept_stats"), "color": mom.get("kept_color")},
                           sums=sums and {"s1": sums["s1"], "s2": sums["s2"],
                                          "s3": sums["s3"], "n": col.n},
                           timing={"render_s": col.render_s,
                                   "stats_s": time.perf_counter() - t0,
                                   "collector": "b", "state_bytes": state_bytes,
                                   "nonfinite_samples": diagnostics["n_nonfinite"],
                                   "sums_layout": layout,
                                   "slots": col.slots, **diagnostics})


#: integrators that have an in-integrator collector (b)
IN_INTEGRATOR = ("transient_path", "transient_prbvolpath")


# one collector: it holds its loaded scene and state arrays of the size of the video's
# statistics (docs/transient.md); seeds and repeated loads of one scene reuse it
@scene_cache(maxsize=1, loads=False)  # its argument is a loaded scene, kept by no record
def _collector(sc, integrator, transform, lam, max_depth, rr_depth, unwarp, slots):
    if integrator == "transient_prbvolpath":
        from .collector_media import MediaStatsCollector as cls
    else:
        from .collector import StatsCollector as cls

    return cls(sc, transform=transform, lam=lam, max_depth=max_depth, rr_depth=rr_depth,
               camera_unwarp=unwarp, slots=slots)


# ---------------------------------------------------------------------------------------------
# the loader


def _resolve_collector(scene: TransientScene, collector: str) -> str:
    if collector not in COLLECTORS:
        raise DbenchInputError(f"collector: expected one of {COLLECTORS}, got {collector!r}")
    # the cache key holds the resolved collector: (a) and (b) draw different paths
    if scene.needs_passes:  # step emission, scattering=multiple: built from whole passes
        if collector == "b":
            raise DbenchInputError(f"collector: 'b' sums inside one render; {scene.name} with "
                                   f"{scene.params} (step emission or scattering=multiple) is "
                                   f"made from whole 1-spp passes; use 'a' or 'auto'")
        return "a"
    if collector == "auto":
        return "b" if scene.integrator in IN_INTEGRATOR else "a"
    if collector == "b" and scene.integrator not in IN_INTEGRATOR:
        raise DbenchInputError(f"collector: 'b' needs {' or '.join(IN_INTEGRATOR)}; "
                               f"{scene.name} uses {scene.integrator}; use 'a' or 'auto'")
    return collector


def reference_spp(spp: int, ref_spp: int | None) -> int:
    return int(ref_spp) if ref_spp else max(default_ref(), 16 * int(spp))


def load_transient(scene: str | TransientScene, spp: int, res,
                   needs: Iterable[str] | None = None, transform: str = DEFAULT_TRANSFORM,
                   lam: float = 0.5, seed: int = 0, ref_spp: int | None = None,
                   cache: Cache | None = None, progress: bool = True, bins: int | None = None,
                   collector: str = "auto", ref_seed: int | None = None) -> TransientFrame:
    """A :class:`~dbench.data.TransientFrame` of a transient scene, rendering what is missing.

    Args:
        scene: catalogue name or TransientScene.
        spp: samples per pixel (paths per pixel; each is one sample of every bin).
        res: image size (a side in pixels, ``"WxH"`` or (width, height)).
        needs: buffers (``color`` always comes; ``stats`` adds ``non_zero``); None = all.
        transform, lam: sample transform of the statistics (default identity, docs/methods/statistical.md §3).
        seed: base seed of the noisy samples and features (disjoint streams).
        ref_spp: reference spp (default max(DBENCH_REF_SPP or 4096, 16·spp)).
        ref_seed: seed of the reference and ``reference_var`` (None means 0), independent of
            ``seed`` so that noisy renders of several seeds share one reference. ``reference``
            brings ``reference_var`` and ``emitter``; ``meta`` then adds ``ref_spp``,
            ``ref_seed``, ``ref_render_s`` and ``ref_rmse`` = sqrt(mean(reference_var)).
        bins: T (default the scene's); the window [start, end) stays the scene's.
        collector: ``"a"`` (1-spp passes, host sums), ``"b"`` (in-integrator) or ``"auto"``
            (b for transient_path and transient_prbvolpath scenes, a otherwise). The color
            comes from the same samples as the statistics, so it does not depend on whether
            ``stats`` was asked for. Scenes made from whole passes (``emission=step``: each
            path's cumsum along T; ``scattering=multiple``: a second render subtracted) use
            (a) whatever is asked for with ``auto`` and refuse ``b``.
    """
    sc = scene if isinstance(scene, Scene) else _scenes.get(scene)
    if not isinstance(sc, TransientScene):
        raise DbenchInputError(f"scene: {sc.name} is a {sc.kind} scene, not a transient one")
    seed = check_render_args(spp, seed, ref_spp)
    res = parse_res(res)
    wanted = set(sc.provides if needs is None else needs) | {"color"}
    unknown = wanted - set(sc.provides)
    if unknown:
        raise DbenchInputError(f"needs: scene {sc.name} cannot provide {sorted(unknown)}; "
                               f"it provides {sorted(sc.provides)}")
    check_transform(transform, lam)

    if "reference" in wanted:
        wanted.add("emitter")
    ref_seed = check_ref_seed(ref_seed)
    window = sc.window(bins)
    check_bins(window.bins, res)  # memory of the film, before anything renders
    _mitransient()
    mi = mitsuba()
    which = _resolve_collector(sc, collector)
    cache = cache or Cache()
    base = {"scene": sc.name, "res": res.key, "dict": sc.transient_dict(mi, res, window),
            "params": sc.params, "versions": versions(), "window": window.meta()}
    meta: dict = {"scene": sc.name, "kind": "transient", "spp": int(spp), "res": res.key,
                  "seed": int(seed), "ev": sc.ev, "versions": base["versions"],
                  **window.meta(), "camera_unwarp": sc.camera_unwarp, "max_depth": sc.max_depth,
                  "integrator": sc.integrator, "emitter": sc.emitter_meta,
                  "scene_params": dict(sc.params), "medium": sc.medium, "collector": which, "cache_hits": [], "rendered": []}

    copies = batch_copies(res, window.bins, spp) if which == "a" else 1
    noisy_desc = {**base, "what": "transient-noisy", "spp": int(spp), "seed": int(seed),
                  "collector": which, "copies": copies, "nonfinite": NONFINITE_VERSION}
    stats_desc = {**noisy_desc, "what": "transient-stats", "transform": transform,
                  "lam": float(lam), "total_var": TOTAL_VAR_VERSION}
    noisy = cache.get("transient-noisy", noisy_desc)
    st_entry = cache.get("transient-stats", stats_desc) if "stats" in wanted else None
    stats = non_zero = total_var = None
    if noisy is not None and ("stats" not in wanted or st_entry is not None):
        arrays = noisy.arrays()
        color, steady = arrays["color"], arrays["steady"]
        meta.update(render_s=noisy.meta.get("render_s"),
                    nonfinite_samples=noisy.meta.get("nonfinite_samples"))
        meta["cache_hits"].append("color")
        if st_entry is not None:
            sa = st_entry.arrays()
            stats = SampleStats(n=float(spp), mean=sa["mean"], var_mean=sa["var_mean"],
                                m3=sa["m3"], transform=transform, lam=float(lam),
                                diagnostics=st_entry.meta.get("diagnostics", {}))
            non_zero = sa["non_zero"]
            total_var = sa.get("total_var")
            meta.update(stats_s=st_entry.meta.get("stats_s"))
            meta["cache_hits"].append("stats")
    else:
        if which == "b":
            out = collect_in_integrator(sc, res, spp, seed, bins, transform, lam,
                                        rows=cache.enabled, stats="stats" in wanted)
        else:
            out = collect_passes(sc, res, spp, seed, bins,
                                 (transform, lam) if "stats" in wanted else None,
                                 copies=copies, progress=progress)
        color, steady, rows, kept = out.color, out.steady, out.rows or {}, out.kept or {}
        meta.update(render_s=out.timing["render_s"],
                    nonfinite_samples=out.timing["nonfinite_samples"])
        meta["rendered"].append("color")
        if noisy is None:
            cache.put("transient-noisy", noisy_desc, arrays={"color": color, "steady": steady},
                      meta={"render_s": out.timing["render_s"], "timing": dict(out.timing),
                            "nonfinite_samples": out.timing["nonfinite_samples"]},
                      compress=False, sparse=("color",), rows=rows.get("color"),
                      kept=kept.get("color"))
        if out.stats is not None and "stats" in wanted:
            stats, non_zero, total_var = out.stats, out.non_zero, out.total_var
            meta.update(stats_s=out.timing["stats_s"])
            if "sums_layout" in out.timing:  # collector (b): packets or compact (voxel_sums.py)
                meta["sums_layout"] = out.timing["sums_layout"]
            meta["rendered"].append("stats")
            totals = {} if total_var is None else {"total_var": total_var}
            cache.put("transient-stats", stats_desc,
                      arrays={"mean": stats.mean, "var_mean": stats.var_mean, "m3": stats.m3,
                              "non_zero": non_zero, **totals},
                      meta={"stats_s": out.timing["stats_s"],
                            "diagnostics": stats.diagnostics},
                      # deflating took 12-25x the write time for half the size; the empty
                      # (pixel, bin) rows are left out instead (datasets/sparse_rows.py)
                      compress=False, sparse=("mean", "var_mean", "m3", "non_zero"),
                      rows=rows.get("stats"), kept=kept.get("stats"))
    if stats is not None:
        meta["stats_diagnostics"] = dict(stats.diagnostics)
    # collector (b)'s steady image is one mi.render of all spp: a pixel a NaN or ±Inf sample
    # reached is NaN, which counts as 0 as a whole (a cached entry's too); its count is (b)'s
    steady = zeroed(steady)[0]
    meta["energy_fraction"] = energy_fraction(color, steady, sc.emission)
    meta["window_covers_all"] = bool(meta["energy_fraction"] >= COVERS_ALL)

    buffers: dict[str, np.ndarray] = {}
    feats_wanted = wanted & {"albedo", "normal", "depth", "position", "emitter"}
    if feats_wanted:
        fsc = sc.feature_scene
        feat_desc = {"scene": sc.name, "res": res.key, "dict": fsc.scene_dict(mi, res),
                     "versions": base["versions"], "what": "transient-features",
                     "spp": _render.DEFAULT_FEATURE_SPP, "seed": int(seed),
                     "aovs": _render.AOV_STRING}
        feats = _render.cached_features(cache, feat_desc, fsc, res, seed, meta)
        buffers.update({k: feats[k] for k in feats_wanted})

    if "reference" in wanted:
        rspp = reference_spp(spp, ref_spp)
        ref_desc = {**base, "what": "transient-reference", "spp": rspp, "seed": ref_seed,
                    "chunk": DEFAULT_REFERENCE_CHUNK, "var": _render.REFERENCE_VAR_VERSION,
                    "nonfinite": NONFINITE_VERSION}
        entry = cache.get("transient-reference", ref_desc)
        arrays = entry.arrays() if entry is not None else {}
        if {"reference", "reference_var", "steady"} <= set(arrays):
            ref, ref_var, ref_steady = arrays["reference"], arrays["reference_var"], arrays["steady"]
            meta["ref_render_s"] = entry.meta.get("render_s")
            meta["ref_nonfinite_samples"] = entry.meta.get("nonfinite_samples")
            meta["cache_hits"].append("reference")
        else:
            counts: dict = {}
            ref, ref_var, ref_steady, seconds = render_reference(sc, res, rspp, ref_seed, bins,
                                                                 progress=progress,
                                                                 counts=counts)
            cache.put("transient-reference", ref_desc,
                      arrays={"reference": ref, "reference_var": ref_var, "steady": ref_steady},
                      sparse=("reference", "reference_var"),
                      meta={"render_s": seconds, **counts,
                            "chunks": len(_render.reference_chunks(rspp,
                                                                   DEFAULT_REFERENCE_CHUNK))})
            meta["ref_render_s"] = seconds
            meta["ref_nonfinite_samples"] = counts["nonfinite_samples"]
            meta["rendered"].append("reference")
        buffers["reference"], buffers["reference_var"] = ref, ref_var
        meta.update(reference_meta(rspp, ref_seed, ref_var))
        meta["reference_energy_fraction"] = energy_fraction(ref, ref_steady, sc.emission)

    return TransientFrame(color=color, stats=stats, steady=steady,
                          non_zero=None if non_zero is None else non_zero,
                          meta=note_nonfinite(meta, per_path=which == "a"),
                          total_var=total_var, **buffers)


__all__ = ["TransientScene", "Window", "TransientRender", "load_transient", "collect_passes",
           "collect_in_integrator", "pass_samples", "render_plain", "render_reference",
           "size_window", "direct_arrivals", "direct_arrival_dict", "expected_direct_bins",
           "energy_fraction", "transient_film", "SPEED_OF_LIGHT"]
