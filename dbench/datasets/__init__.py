"""Datasets: ``load(scene, spp, res, needs)`` renders what is missing and reuses the cache.

Steady buffers: ``color`` and ``stats`` (the noisy samples, seed ``seed``), ``albedo``,
``normal``, ``depth``, ``position`` and ``emitter`` (one cached feature render at max(64, spp)
spp, box filter), ``reference`` with ``reference_var`` (the variance of the reference mean from
K ≥ 16 independent chunks; seed ``ref_seed``, independent of ``seed`` so that N noisy seeds
share one reference). Whenever ``reference`` is loaded, ``emitter`` comes with it (the judge
separates lights seen directly or in smooth mirrors from surfaces). :func:`scene_fingerprint`
names a scene's content.

Example:
    >>> from dbench import datasets
    >>> frame = datasets.load("cornell", spp=4, res=16, needs={"color", "albedo"})  # doctest: +SKIP
    >>> frame.color.shape, frame.stats is None  # doctest: +SKIP
    ((16, 16, 3), True)
"""
from __future__ import annotations

import os
from typing import Iterable

import numpy as np

from ..data import Frame, SampleStats, Sequence, TransientFrame, check_transform
from ..errors import DbenchInputError
from ..resolution import Res, parse_res
from . import emitter as _emitter
from . import render as _render
from .scenes import catalogue as _scenes
from .sequence import load as _sequence  # registers the sequence scenes
from .transient import load as _transient  # registers the transient scenes
from .cache import Cache, make_key
from .mitsuba_env import focus, mitsuba, versions
from .nonfinite import NONFINITE_VERSION, note_nonfinite
from .references import check_ref_seed, check_render_args, reference_meta, reference_spp
from .scenes.catalogue import Scene
from .scenes.build import check_plugin_scene
from .stats import stats_from_arrays, stats_to_arrays

FEATURES = ("albedo", "normal", "depth", "position")
#: Buffers of the cached feature render (FEATURES plus the emitter coverage).
FEATURE_BUFFERS = FEATURES + ("emitter",)

available_scenes = _scenes.available
get_scene = _scenes.get


def _base_description(scene: Scene, res: Res) -> dict:
    mi = mitsuba()
    # a scene file is its content (its key_dict hashes every file it reads), not its name:
    # a renamed copy keeps its renders and cells (README.md, "Mitsuba scene files")
    name = getattr(scene, "identity_name", None) or scene.name
    return {"scene": name, "res": res.key, "dict": scene.key_dict(mi, res),
            "params": scene.params, "versions": versions()}


def feature_identity(scene: str | Scene, spp: int) -> dict:
    """The part of a result's identity that the feature buffers' sample count adds: {} where it
    is DEFAULT_FEATURE_SPP (every result made before the count followed the colour's, which
    keeps its identity), else {"feature_spp": n} for rendered steady scenes
    (:func:`~dbench.datasets.render.feature_spp`). Sequences (matched G-buffer), transient
    scenes and folders of renders do not render steady features by this rule."""
    sc = scene if isinstance(scene, Scene) else _scenes.get(scene)
    n = _render.feature_spp(spp)
    if sc.kind != "steady" or isinstance(sc, _scenes.FolderScene) \
            or n == _render.DEFAULT_FEATURE_SPP:
        return {}
    return {"feature_spp": n}


def scene_fingerprint(scene: str | Scene, res) -> str:
    """A short content hash (16 hex chars of sha256) of ``scene`` at ``res``: the canonical
    scene description (the Mitsuba dictionary through :func:`~dbench.datasets.cache.canonical`,
    ``params``, renderer :func:`versions`); every frame's dictionary for sequence scenes, the
    transient dictionary with the default window for transient scenes; a folder of renders,
    steady or a sequence, by its own key (the content hash of the files it uses,
    docs/formats.md §1); the tone map's ``ev`` where it is not 0. Renders nothing.
    Two results with the same fingerprint were rendered from the same scene content."""
    sc = scene if isinstance(scene, Scene) else _scenes.get(scene)
    res = parse_res(res)
    mi = mitsuba()
    # a folder holding a sequence is read, not rendered: it has no frame dictionaries, and its
    # key_dict (below) already names its content, as a steady folder's does
    if sc.kind == "sequence" and not isinstance(sc, _scenes.FolderScene):
        desc = {"scene": sc.name, "kind": sc.kind, "res": res.key, "n_frames": int(sc.n_frames),
                "frames": [sc.frame_dict(mi, res, i) for i in range(sc.n_frames)],
                "params": sc.params, "versions": versions(),
                # how the G-buffer and the A-SVGF gradient samples are made changes the inputs
                "gbuffer": f"psr-{_sequence.PSR_VERSION}",
                "gradient": f"reshade-{_sequence.RESHADE_VERSION}",
                "motion": _sequence.MOTION_VERSION,
                # how the passes of a noisy frame are summed (datasets/sequence/frames.py)
                "samples": _sequence.SAMPLES_VERSION}
    elif sc.kind == "transient":
        window = sc.window()
        desc = {"scene": sc.name, "kind": sc.kind, "res": res.key,
                "dict": sc.transient_dict(mi, res, window), "window": window.meta(),
                "params": sc.params, "versions": versions()}
    else:
        # how the noisy samples are drawn (the one-pass kernel, datasets/render_moments.py)
        # changes every noisy image, so a cell made before it is another result
        desc = {**_base_description(sc, res), "kind": sc.kind,
                "samples": _render.SAMPLES_VERSION}
    # the emitter buffer feeds the surface metrics and the methods that keep lights
    desc["emitter"] = _emitter.EMITTER_VERSION
    if float(sc.ev) != 0.0:
        # the tone map's exposure changes the LDR metrics (PSNR, SSIM, FLIP) and pictures,
        # not the renders; named only where it is set, so every scene at 0 EV keeps its
        # fingerprint and cells
        desc["ev"] = float(sc.ev)
    return make_key(desc)[:16]


def default_transform(kind: str) -> str:
    """The statistics' sample transform of a scene of ``kind`` when none is asked
    (docs/methods/statistical.md §3): identity for transient scenes, Box-Cox for the others."""
    return _transient.DEFAULT_TRANSFORM if kind == "transient" else "box-cox"


def load(scene: str | Scene, spp: int, res, needs: Iterable[str] | None = None,
         transform: str | None = None, lam: float = 0.5, seed: int = 0,
         ref_spp: int | None = None, cache: Cache | None = None, progress: bool = True,
         frames: int | None = None, bins: int | None = None,
         collector: str = "auto", ref_seed: int | None = None
         ) -> Frame | Sequence | TransientFrame:
    """Return a :class:`~dbench.data.Frame` of ``scene`` with exactly the buffers in ``needs``.

    Sequence scenes (kind ``sequence``) return a :class:`~dbench.data.Sequence` instead, built by
    :func:`dbench.datasets.sequence.load.load_sequence` (``frames`` limits the frame count).
    Transient scenes (kind ``transient``) return a :class:`~dbench.data.TransientFrame` built by
    :func:`dbench.datasets.transient.load.load_transient` (``bins``: time bins T; ``collector``:
    ``"a"``, ``"b"`` or ``"auto"``, see that module); both options apply to them only.

    Args:
        scene: catalogue name or Scene.
        spp: samples per pixel of the noisy color (and its statistics).
        res: image size: a side in pixels (square), ``"WxH"`` or (width, height)
            (:func:`dbench.resolution.parse_res`).
        needs: buffer names (``color`` always comes); None means every buffer the scene provides.
        transform, lam: sample transform of the statistics (docs/methods/statistical.md §3); None
            means the kind's default: Box-Cox for steady scenes, identity for transient ones.
        seed: base seed of the noisy passes and the features (disjoint seed streams).
        ref_spp: reference spp (default ``DBENCH_REF_SPP`` or 4096).
        cache: a :class:`Cache` (default location when None).
        ref_seed: seed of the reference and its variance (None means 0), independent of
            ``seed``: noisy renders with seeds s … s+N−1 share one cached reference.
    Returns:
        Frame whose ``meta`` holds the settings, render timings and cache hits; with a
        reference also ``ref_spp``, ``ref_seed``, ``ref_render_s`` (seconds the reference took,
        from the cache entry when cached) and ``ref_rmse`` = sqrt(mean(reference_var)).
    """
    if not isinstance(scene, (str, os.PathLike, Scene)):
        raise DbenchInputError(f"scene: expected a catalogue name, a scene file or folder, or a "
                               f"Scene, got {scene!r}")
    if needs is not None and (isinstance(needs, (str, bytes)) or not isinstance(
            needs, Iterable)):  # a string would read as its letters
        raise DbenchInputError(f"needs: expected a collection of buffer names (e.g. "
                               f"{{'color', 'reference'}}), got {needs!r}")
    if cache is not None and not isinstance(cache, Cache):
        raise DbenchInputError(f"cache: expected a dbench.datasets.Cache, got {cache!r}")
    sc = scene if isinstance(scene, Scene) else _scenes.get(os.fspath(scene))
    # another scene's loaded objects would slow every render of this one (mitsuba_env.focus)
    focus(sc.objects_key())
    if not sc.renders:
        return _load_folder_scene(sc, spp, res, needs, seed, ref_spp, frames, transform, lam)
    transform = transform or default_transform(sc.kind)
    if sc.kind == "sequence":
        return _sequence.load_sequence(sc, spp=spp, res=res, needs=needs, seed=seed,
                                       ref_spp=ref_spp, cache=cache, progress=progress,
                                       frames=frames, ref_seed=ref_seed,
                                       transform=transform, lam=lam)
    if sc.kind == "transient":
        return _transient.load_transient(sc, spp=spp, res=res, needs=needs,
                                         transform=transform,
                                         lam=lam, seed=seed, ref_spp=ref_spp, cache=cache,
                                         progress=progress, bins=bins, collector=collector,
                                         ref_seed=ref_seed)
    seed = check_render_args(spp, seed, ref_spp)
    res = parse_res(res)
    for name, value in (("frames", frames), ("bins", bins)):  # not silently left unread
        if value is not None:
            raise DbenchInputError(f"{name}: {sc.name} is a {sc.kind} scene; only "
                                   f"{'sequence' if name == 'frames' else 'transient'} scenes "
                                   f"take {name}")
    if collector != "auto":
        raise DbenchInputError(f"collector: {sc.name} is a steady scene; only transient scenes "
                               f"take a collector")
    check_transform(transform, lam)  # whether or not the statistics are asked for
    check_plugin_scene(sc)  # a plugin's unknown Mitsuba type: exit 2 before anything renders
    wanted = set(sc.provides if needs is None else needs) | {"color"}
    unknown = wanted - set(sc.provides)
    if unknown:
        raise DbenchInputError(f"needs: scene {sc.name} cannot provide {sorted(unknown)}; "
                               f"it provides {sorted(sc.provides)}")
    if "reference" in wanted:
        wanted.add("emitter")
    ref_seed = check_ref_seed(ref_seed)
    cache = cache or Cache()
    ref_spp = ref_spp or reference_spp()
    base = _base_description(sc, res)
    meta: dict = {"scene": sc.name, "kind": sc.kind, "spp": int(spp), "res": res.key,
                  "seed": int(seed), "ev": sc.ev, "versions": base["versions"], "cache_hits": [],
                  "rendered": [],
                  # a scene file's render as it differs from the file (datasets.scene_fidelity)
                  **getattr(sc, "frame_meta", {})}
    if "scene_file" in meta:  # its settings in words, the film as rendered at this size
        from .scene_files.fidelity import report_lines
        meta["scene_file_settings"] = report_lines(meta["scene_file"], res, spp, seed)

    # (NONFINITE_VERSION: entries made before the counts were kept are not read as new)
    noisy_desc = {**base, "what": "noisy", "spp": int(spp), "seed": int(seed),
                  "copies": _render.batch_size(res, spp), "samples": _render.SAMPLES_VERSION,
                  "nonfinite": NONFINITE_VERSION}
    stats_desc = {**noisy_desc, "what": "stats", "transform": transform, "lam": float(lam)}
    color_entry = cache.get("noisy", noisy_desc)
    stats_entry = cache.get("stats", stats_desc) if "stats" in wanted else None
    stats: SampleStats | None = None
    if color_entry is not None and ("stats" not in wanted or stats_entry is not None):
        color = color_entry.images()["color"]
        meta.update(render_s=color_entry.meta.get("render_s"),
                    nonfinite_samples=color_entry.meta.get("nonfinite_samples"))
        meta["cache_hits"].append("color")
        if stats_entry is not None:
            stats = stats_from_arrays(stats_entry.arrays(), transform, lam)
            meta.update(stats_s=stats_entry.meta.get("stats_s"))
            meta["cache_hits"].append("stats")
    else:
        want_stats = (transform, lam) if "stats" in wanted else None
        color, stats, timing = _render.render_passes(sc, res, spp, seed, want_stats, progress)
        meta.update(render_s=timing["render_s"], nonfinite_samples=timing["nonfinite_samples"])
        meta["rendered"].append("color")
        if color_entry is None:
            cache.put("noisy", noisy_desc, images={"color": color}, compress_images=False,
                      meta={"render_s": timing["render_s"], "copies": timing["copies"],
                            "nonfinite_samples": timing["nonfinite_samples"]})
        if stats is not None:
            meta.update(stats_s=timing["stats_s"])
            meta["rendered"].append("stats")
            cache.put("stats", stats_desc, arrays=stats_to_arrays(stats),
                      meta={"stats_s": timing["stats_s"], "render_s": timing["render_s"],
                            "diagnostics": stats.diagnostics})

    buffers: dict[str, np.ndarray] = {}
    if wanted & set(FEATURE_BUFFERS):
        fspp = _render.feature_spp(spp)
        feat_desc = {**base, "what": "features", "spp": fspp, "seed": int(seed),
                     "aovs": _render.AOV_STRING}
        feats = _render.cached_features(cache, feat_desc, sc, res, seed, meta, fspp)
        meta["feature_spp"] = fspp
        buffers.update({k: feats[k] for k in FEATURE_BUFFERS if k in wanted})

    if "reference" in wanted:
        ref_desc = {**base, "what": "reference", "spp": int(ref_spp), "seed": ref_seed,
                    "chunk": _render.DEFAULT_REFERENCE_CHUNK,
                    "var": _render.REFERENCE_VAR_VERSION, "samples": _render.SAMPLES_VERSION,
                    "nonfinite": NONFINITE_VERSION}
        entry = cache.get("reference", ref_desc)
        images = entry.images() if entry is not None else {}
        if "reference" in images and "reference_var" in images:
            buffers["reference"] = images["reference"]
            buffers["reference_var"] = images["reference_var"]
            meta["ref_render_s"] = entry.meta.get("render_s")
            meta["ref_nonfinite_samples"] = entry.meta.get("nonfinite_samples")
            meta["cache_hits"].append("reference")
        else:
            counts: dict = {}
            ref, ref_var, seconds = _render.render_reference(sc, res, ref_spp, ref_seed,
                                                             progress=progress, counts=counts)
            cache.put("reference", ref_desc, images={"reference": ref, "reference_var": ref_var},
                      meta={"render_s": seconds, "chunks": len(_render.reference_chunks(ref_spp)),
                            **counts},
                      compress_images=False)
            meta["ref_nonfinite_samples"] = counts.get("nonfinite_samples")
            buffers["reference"], buffers["reference_var"] = ref, ref_var
            meta["ref_render_s"] = seconds
            meta["rendered"].append("reference")
        meta.update(reference_meta(ref_spp, ref_seed, buffers["reference_var"]))
    note_nonfinite(meta)  # the warning of their counts (datasets/nonfinite.py)
    return Frame(color=color, stats=stats, meta=meta, **buffers)


#: Longer image side of a scene's default size (catalogue scenes: DEFAULT_SIDE²).
DEFAULT_SIDE = 128


def default_res(scene: str | Scene, side: int = DEFAULT_SIDE) -> Res:
    """The size a scene is rendered at when none is asked for: a folder of renders its own
    size; a Mitsuba scene file its film's aspect ratio with the longer side ``side``; any
    other scene ``side`` × ``side``."""
    sc = _scenes.get(scene)
    if isinstance(sc, _scenes.FolderScene):
        return Res(sc.info.width, sc.info.height)
    from .scene_files.load import XmlScene, file_film_size

    if isinstance(sc, XmlScene):
        w, h = file_film_size(sc)
        scale = side / max(w, h)
        return Res(max(1, round(w * scale)), max(1, round(h * scale)))
    return Res(side, side)


def _load_folder_scene(sc: Scene, spp: int, res, needs, seed: int, ref_spp: int | None,
                       frames: int | None, transform: str | None = None,
                       lam: float = 0.5) -> Frame | Sequence:
    """A frame (or, for numbered frames, a sequence) read from a folder of renders
    (dbench.datasets.folders.load). Settings that cannot apply to files are refused: another size,
    another reference spp, a seed other than the first (a folder holds one noisy image per
    spp), a ``transform`` (with its ``lam``) other than the one its statistics were gathered
    with (None: theirs), more ``frames`` than the folder numbers."""
    from .folders.load import load_folder

    info = sc.info
    where = f"{info.path}/{info.name}"
    if res is not None and parse_res(res) != Res(info.width, info.height):
        raise DbenchInputError(f"--res: {where} holds {info.width}x{info.height} images; "
                               f"got {parse_res(res)}")
    if seed != 0:
        raise DbenchInputError(f"--seed/--seeds: {where} holds one noisy image per spp, "
                               f"made with one seed; seed {seed} was asked for (a folder "
                               f"offers --seed 0 and --seeds 1)")
    if ref_spp is not None and info.ref_spp is not None and int(ref_spp) != int(info.ref_spp):
        raise DbenchInputError(f"--ref-spp: the reference in {where} has {info.ref_spp} spp; "
                               f"got {ref_spp}")
    if ref_spp is not None and info.ref_spp is None:  # it would be read as said and ignored
        raise DbenchInputError(f"--ref-spp: the reference in {where} states no spp, and a "
                               f"file's spp is not an option of the run; declare it in the "
                               f"folder's dataset.json (\"ref_spp\": {ref_spp}, docs/formats.md) "
                               f"or leave --ref-spp out")
    if needs is None or "stats" in needs:
        check_folder_transform(sc, spp, transform, lam)
    if info.frames is None:
        return load_folder(info, spp, needs)
    check_folder_frames(sc, frames)
    numbers = list(info.frames)[:frames] if frames else list(info.frames)
    out = [load_folder(info, spp, needs, frame=k) for k in numbers]
    meta = {**out[0].meta, "kind": "sequence", "frames": len(out)}
    return Sequence(out, meta=meta)


def check_folder_frames(sc: Scene, frames: int | None) -> None:
    """Refuse ``frames`` above the count of the folder scene ``sc``'s numbered frames, rather
    than run fewer than asked (a catalogue sequence refuses more than it has)."""
    info = sc.info
    if info.frames is not None and frames is not None and not 1 <= int(frames) <= len(
            info.frames):
        raise DbenchInputError(f"--frames: {info.path}/{info.name} holds {len(info.frames)} "
                               f"numbered frames ({info.frames[0]}-{info.frames[-1]}); expected "
                               f"an integer in [1, {len(info.frames)}], got {frames}")


def check_folder_transform(sc: Scene, spp: int, transform: str | None, lam: float,
                           option: str = "--transform") -> None:
    """Refuse a ``transform`` (with its ``lam``; None: the folder's own) other than the one the
    statistics of the folder scene ``sc`` at ``spp`` were gathered with
    (``FolderInfo.stats_settings``, read when the folder was scanned): its statistics are read
    as they are, so reading them as asked would be a silent change of the run's settings.
    ``option``: what the message names (``--lam`` when only λ was given, with the folder's own
    transform)."""
    held = sc.info.stats_settings.get(int(spp))
    if transform is None or held is None:
        return

    def named(name: str, value) -> str:  # identity has no λ
        return name if name == "identity" else f"{name} (λ {float(value)})"

    if named(*held) != named(transform, lam):
        raise DbenchInputError(f"{option}: the statistics in {sc.info.path}/{sc.info.name} "
                               f"were gathered with {named(*held)}; {named(transform, lam)} "
                               f"was asked for (give theirs, or leave {option} out)")


__all__ = ["load", "available_scenes", "get_scene", "Cache", "Scene", "FEATURES",
           "FEATURE_BUFFERS", "scene_fingerprint", "feature_identity", "default_res",
           "default_transform", "check_folder_frames", "check_folder_transform"]
