"""Training sets rendered here from the procedural training scenes, cached, and batches of crops.

``build_training_set`` renders, for each training scene, noisy images at several spp (one
independent seed per spp), the AOV features and a reference, all through
:func:`dbench.datasets.load` and therefore through the content-addressed render cache: a second
build reads everything back. Scenes whose quick probe render is nearly black are skipped (they
would teach nothing) and the next index is used, deterministically.

Arrays of a :class:`TrainingSet` (S scenes, P sample counts, square H = W = res):

* ``noisy`` (S, P, H, W, 3) linear radiance; ``spp`` (P,) the sample counts;
* ``reference`` (S, H, W, 3); ``albedo`` (S, H, W, 3); ``normal`` (S, H, W, 3);
* ``depth`` (S, H, W, 1), already divided by the frame's largest depth (docs/methods/autoencoder.md §1).

``TrainingSet.hash`` is a SHA-256 of every array and the settings: the "data hash" written beside
the shipped weights.
"""
from __future__ import annotations

import hashlib
import json
import time
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from ..data import check_buffer
from ..errors import DbenchInputError
from .scenes import training_scene

DEFAULT_SPP = (1, 2, 4, 8)


def _check_parts(data, ref_lead: tuple, feature_lead: tuple) -> None:
    """Check (and convert) the reference, albedo, normal and depth arrays of a training or
    sequence set against the leading dimensions its noisy array implies."""
    data.reference = check_buffer("reference", data.reference, (*ref_lead, 3))
    data.albedo = check_buffer("albedo", data.albedo, (*feature_lead, 3))
    data.normal = check_buffer("normal", data.normal, (*feature_lead, 3))
    data.depth = check_buffer("depth", data.depth, (*feature_lead, 1))
    if len(data.scenes) != ref_lead[0]:
        raise DbenchInputError(f"scenes: expected {ref_lead[0]} names, got {len(data.scenes)}")


@dataclass
class _RenderedSet:
    """The arrays, sample counts, scene names and settings every training set holds."""

    noisy: np.ndarray
    spp: tuple[int, ...]
    reference: np.ndarray
    albedo: np.ndarray
    normal: np.ndarray
    depth: np.ndarray
    scenes: list[str]
    config: dict[str, Any] = field(default_factory=dict)

    @property
    def hash(self) -> str:
        """SHA-256 of the arrays (float32 bytes), spp and scene names."""
        d = hashlib.sha256()
        for a in (self.noisy, self.reference, self.albedo, self.normal, self.depth):
            d.update(np.ascontiguousarray(a, np.float32).tobytes())
        d.update(json.dumps({"spp": list(self.spp), "scenes": self.scenes}).encode())
        return d.hexdigest()


@dataclass
class TrainingSet(_RenderedSet):
    def __post_init__(self) -> None:
        self.noisy = check_buffer("noisy", self.noisy, (None, len(self.spp), None, None, 3))
        s, _, h, w, _ = self.noisy.shape
        _check_parts(self, (s, h, w), (s, h, w))

    @property
    def shape(self) -> tuple[int, int, int]:
        s, _, h, w, _ = self.noisy.shape
        return s, h, w

    def emitter_pixels(self, min_radiance: float = 1.0) -> list[np.ndarray]:
        """Per scene, the (n, 2) row/column indices of directly visible lights: pixels whose
        albedo is black (emitters carry a black BSDF, ``learn.scenes``) and whose reference
        exceeds ``min_radiance`` in some channel. Cached per threshold."""
        cache = self.__dict__.setdefault("_emitter_cache", {})
        if min_radiance not in cache:
            cache[min_radiance] = [
                np.argwhere((a.max(-1) < 0.02) & (r.max(-1) > min_radiance))
                for a, r in zip(self.albedo, self.reference)]
        return cache[min_radiance]



def _finite(x: np.ndarray) -> np.ndarray:
    return np.where(np.isfinite(x), x, 0.0).astype(np.float32)


def normalize_depth(depth: np.ndarray) -> np.ndarray:
    """(H, W, 1) depth -> divided by its largest finite value (0 where not hit or non-finite)."""
    d = np.maximum(_finite(depth), 0.0)
    m = float(d.max()) if d.size else 0.0
    return (d / m if m > 0 else d).astype(np.float32)


def probe_mean(scene, res: int = 32, spp: int = 16) -> float:
    """Mean radiance of a quick render, used to skip nearly black training scenes."""
    from ..datasets.mitsuba_env import mitsuba

    mi = mitsuba()
    sc = mi.load_dict(scene.scene_dict(mi, res))
    return float(np.mean(np.array(mi.render(sc, spp=spp, seed=7))))


def build_training_set(n_scenes: int = 24, res: int = 128, spp: Sequence[int] = DEFAULT_SPP,
                       ref_spp: int = 1024, family_seed: int = 0, cache=None,
                       min_mean: float = 0.03, progress: bool = True,
                       features_with: str = "first") -> TrainingSet:
    """Render (or read from the cache) ``n_scenes`` procedural training scenes.

    Noisy images at spp[p] use seed p (independent sample streams); the reference uses seed 0.
    The features come with the render at spp[0] (``features_with="first"``: seed 0,
    max(64, spp[0]) samples, :func:`dbench.datasets.render.feature_spp`) or with the one at
    spp[-1] (``"last"``: its seed and max(64, spp[-1]) samples, never noisier than any input,
    as the benchmark's features at high spp). Returns a :class:`TrainingSet`; ``config``
    records the settings and render times.
    """
    from .. import datasets

    if features_with not in ("first", "last"):
        raise ValueError(f"features_with: expected 'first' or 'last', got {features_with!r}")
    cache = cache or datasets.Cache()
    noisy, refs, albedo, normal, depth, names, skipped = [], [], [], [], [], [], []
    t0 = time.perf_counter()
    index = 0
    feature_needs = {"albedo", "normal", "depth"}
    first = features_with == "first"
    while len(names) < n_scenes:
        sc = training_scene(index, family_seed)
        index += 1
        if probe_mean(sc) < min_mean:
            skipped.append(sc.name)
            continue
        base = datasets.load(sc, spp=int(spp[0]), res=res,
                             needs={"color", "reference"} | (feature_needs if first else set()),
                             seed=0, ref_spp=ref_spp, cache=cache, progress=False)
        loads = [base] + [datasets.load(sc, spp=int(n), res=res,
                                        needs={"color"} | (feature_needs if p == len(spp) - 1
                                                           and not first else set()),
                                        seed=p, cache=cache, progress=False)
                          for p, n in enumerate(spp[1:], start=1)]
        feats = loads[0 if first else -1]
        noisy.append(np.stack([_finite(f.color) for f in loads]))
        refs.append(_finite(base.reference))
        albedo.append(np.clip(_finite(feats.albedo), 0, 1))
        normal.append(np.clip(_finite(feats.normal), -1, 1))
        depth.append(normalize_depth(feats.depth))
        names.append(sc.name)
        if progress:
            print(f"  {sc.name}: rendered {base.meta['rendered'] or 'nothing'} "
                  f"({time.perf_counter() - t0:.0f} s so far)", flush=True)
    config = {"n_scenes": n_scenes, "res": res, "spp": list(map(int, spp)),
              "ref_spp": ref_spp, "features_with": features_with, "family_seed": family_seed,
              "min_mean": min_mean,
              "skipped_dark": skipped, "build_s": round(time.perf_counter() - t0, 1)}
    return TrainingSet(noisy=np.stack(noisy), spp=tuple(int(s) for s in spp),
                       reference=np.stack(refs), albedo=np.stack(albedo),
                       normal=np.stack(normal), depth=np.stack(depth), scenes=names,
                       config=config)


def synthetic_training_set(n_scenes: int = 4, res: int = 32, spp: Sequence[int] = (1, 4),
                           seed: int = 0) -> TrainingSet:
    """A tiny rendering-free training set for tests: smooth shading times a blocky albedo, with
    Poisson-like noise that shrinks as 1/sqrt(spp)."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:res, 0:res].astype(np.float32) / res
    noisy, refs, alb, nrm, dep = [], [], [], [], []
    for s in range(n_scenes):
        f = rng.uniform(1, 4, 2)
        light = 0.6 + 0.5 * np.sin(2 * np.pi * f[0] * x + s) * np.cos(2 * np.pi * f[1] * y)
        albedo = np.where(((x * 4).astype(int) + (y * 4).astype(int)) % 2 == 0, 0.8, 0.3)
        albedo = albedo[..., None] * rng.uniform(0.5, 1.0, 3)
        ref = (light[..., None] * albedo).astype(np.float32)
        noisy.append(np.stack([np.maximum(ref * (1 + rng.standard_normal(ref.shape)
                                                 / np.sqrt(n)), 0) for n in spp]))
        refs.append(ref)
        alb.append(albedo.astype(np.float32))
        n = np.zeros((res, res, 3), np.float32)
        n[..., 2] = 1
        nrm.append(n)
        dep.append(np.full((res, res, 1), 1.0, np.float32))
    return TrainingSet(noisy=np.stack(noisy), spp=tuple(spp), reference=np.stack(refs),
                       albedo=np.stack(alb), normal=np.stack(nrm), depth=np.stack(dep),
                       scenes=[f"synthetic-{i}" for i in range(n_scenes)],
                       config={"synthetic": True, "seed": seed, "res": res})


def mixed_spp(spp: Sequence[int], allowed: Sequence[int], rng: np.random.Generator
              ) -> list[int]:
    """Indices into ``spp`` whose renders are averaged into one input: the largest drawn
    uniformly from ``allowed``, every smaller allowed index joined with probability ½.

    The renders have independent seeds, so the spp-weighted mean of a subset is an exact
    estimate at the summed sample count: from renders at 1, 2, 4, …, 1024 spp one gets inputs
    at every count from 1 to 2047, spread nearly log-uniformly (the largest member sets the
    octave)."""
    top = int(rng.integers(len(allowed)))
    chosen = [allowed[top]] + [i for i in allowed[:top] if rng.random() < 0.5]
    return sorted(chosen, key=lambda i: spp[i])


def combine_spp(noisy: np.ndarray, spp: Sequence[int], chosen: Sequence[int]) -> np.ndarray:
    """The spp-weighted mean of ``noisy[i]`` over ``chosen`` (independent renders)."""
    if len(chosen) == 1:
        return noisy[chosen[0]]
    weights = np.array([spp[i] for i in chosen], np.float64)
    stack = np.stack([noisy[i] for i in chosen]).astype(np.float64)
    return np.tensordot(weights / weights.sum(), stack, axes=1).astype(np.float32)


def sample_batch(ts: TrainingSet, rng: np.random.Generator, batch: int, crop: int,
                 spp_choices: Sequence[int] | None = None, light_fraction: float = 0.0,
                 mix_spp: bool = False, exposure: bool = False) -> dict[str, np.ndarray]:
    """A batch of random crops with random horizontal/vertical flips (whole deep image).

    Returns arrays (B, crop, crop, C): ``noisy``, ``reference``, ``albedo``, ``normal``,
    ``depth``; and (B,) ``spp``, ``level`` (log2(spp)/10) and ``exposure``. ``spp_choices``
    restricts the noisy sample counts.

    ``mix_spp``: the input is the mean of a random subset of the scene's independent renders
    (:func:`mixed_spp`), so sample counts between the rendered ones occur too.

    ``exposure``: noisy and reference are multiplied by the auto-exposure of the noisy crop
    (:func:`dbench.methods.hdr_input.autoexposure`), as inference scales a whole image; the
    losses then compare exposed radiance, which is what the network sees.

    ``light_fraction``: the share of crops drawn around a directly visible light
    (:meth:`TrainingSet.emitter_pixels`; a crop holding one of its pixels at a uniformly random
    place), from the scenes that show one. Importance sampling of training patches, as in
    KPCN's patch selection: visible lights cover well under 1 % of the pixels, yet their edges
    dominate the linear RMSE of a scene that shows one, and uniform crops almost never teach
    the networks to keep them sharp.
    """
    from ..methods.kernels.hdr_input import autoexposure, noise_level

    s_count, h, w = ts.shape
    if crop > h or crop > w:
        raise DbenchInputError(f"crop: {crop} exceeds the training images ({h}x{w})")
    allowed = [i for i, n in enumerate(ts.spp) if spp_choices is None or n in spp_choices]
    if not allowed:
        raise DbenchInputError(f"spp_choices: none of {spp_choices} in the set's {ts.spp}")
    if not 0.0 <= light_fraction <= 1.0:
        raise DbenchInputError(f"light_fraction: expected a value in [0, 1], got {light_fraction}")
    lights = ts.emitter_pixels() if light_fraction > 0 else []
    lit = [i for i, px in enumerate(lights) if len(px)]
    out: dict[str, list] = {k: [] for k in ("noisy", "reference", "albedo", "normal", "depth")}
    spps, exposures = [], []
    for _ in range(batch):
        around_light = bool(lit) and rng.random() < light_fraction
        s = lit[int(rng.integers(len(lit)))] if around_light else int(rng.integers(s_count))
        if mix_spp:
            chosen = mixed_spp(ts.spp, allowed, rng)
        else:
            chosen = [allowed[int(rng.integers(len(allowed)))]]
        if around_light:
            cy, cx = lights[s][int(rng.integers(len(lights[s])))]
            y0 = int(np.clip(cy - rng.integers(crop), 0, h - crop))
            x0 = int(np.clip(cx - rng.integers(crop), 0, w - crop))
        else:
            y0 = int(rng.integers(h - crop + 1))
            x0 = int(rng.integers(w - crop + 1))
        fy, fx = bool(rng.integers(2)), bool(rng.integers(2))
        sl = (slice(y0, y0 + crop), slice(x0, x0 + crop))
        noisy = combine_spp([ts.noisy[s, i][sl] for i in range(len(ts.spp))], ts.spp, chosen)
        e = autoexposure(noisy) if exposure else 1.0
        items = {"noisy": noisy * np.float32(e), "reference": ts.reference[s][sl] * np.float32(e),
                 "albedo": ts.albedo[s][sl], "normal": ts.normal[s][sl].copy(),
                 "depth": ts.depth[s][sl]}
        # a flip mirrors the image; the world-space normals are left as rendered (they are
        # features, not screen-space vectors)
        for k, v in items.items():
            if fy:
                v = v[::-1]
            if fx:
                v = v[:, ::-1]
            out[k].append(np.ascontiguousarray(v))
        spps.append(sum(ts.spp[i] for i in chosen))
        exposures.append(e)
    result = {k: np.stack(v).astype(np.float32) for k, v in out.items()}
    result["spp"] = np.array(spps, np.int64)
    result["level"] = np.array([noise_level(n) for n in spps], np.float32)
    result["exposure"] = np.array(exposures, np.float32)
    return result


def full_images(ts: "TrainingSet", p: int, exposure: bool = False) -> dict[str, np.ndarray]:
    """Every scene of ``ts`` at its p-th sample count as one batch (validation): the keys of
    :func:`sample_batch`, each image scaled by its own auto-exposure when ``exposure``."""
    from ..methods.kernels.hdr_input import autoexposure, noise_level

    e = np.array([autoexposure(x) if exposure else 1.0 for x in ts.noisy[:, p]], np.float32)
    scale = e[:, None, None, None]
    n = ts.noisy.shape[0]
    return {"noisy": ts.noisy[:, p] * scale, "reference": ts.reference * scale,
            "albedo": ts.albedo, "normal": ts.normal, "depth": ts.depth,
            "spp": np.full(n, ts.spp[p], np.int64),
            "level": np.full(n, noise_level(ts.spp[p]), np.float32), "exposure": e}


@dataclass
class SequenceSet(_RenderedSet):
    """Camera-animated training sequences (:func:`~dbench.learn.scenes.training_sequence`) for
    the recurrent autoencoder. S sequences, P sample counts, F frames, square H = W:

    * ``noisy`` (S, P, F, H, W, 3); ``albedo``, ``normal`` (S, P, F, H, W, 3) and ``depth``
      (S, P, F, H, W, 1), the G-buffer matched to the colour samples as in the temporal
      datasets (so it differs per spp), depth divided by each frame's largest depth;
    * ``reference`` (S, F, H, W, 3).
    """

    def __post_init__(self) -> None:
        self.noisy = check_buffer("noisy", self.noisy, (None, len(self.spp), None, None, None, 3))
        s, p, f, h, w, _ = self.noisy.shape
        _check_parts(self, (s, f, h, w), (s, p, f, h, w))



def build_sequence_set(n_sequences: int = 16, n_frames: int = 8, res: int = 96,
                       spp: Sequence[int] = (1, 4), ref_spp: int = 256, family_seed: int = 0,
                       cache=None, min_mean: float = 0.03, progress: bool = True
                       ) -> SequenceSet:
    """Render (or read from the cache) ``n_sequences`` training sequences through
    :func:`dbench.datasets.sequence.load.load_sequence` (noisy frames at each spp with seed = its
    index, matched G-buffer, references at ``ref_spp``); nearly black scenes are skipped as in
    :func:`build_training_set`."""
    from .. import datasets
    from ..datasets.sequence.load import load_sequence
    from .scenes import training_sequence

    cache = cache or datasets.Cache()
    noisy, refs, albedo, normal, depth, names, skipped = [], [], [], [], [], [], []
    t0 = time.perf_counter()
    index = 0
    while len(names) < n_sequences:
        sc = training_scene(index, family_seed)
        seq_scene = training_sequence(index, n_frames, family_seed)
        index += 1
        if probe_mean(sc) < min_mean:
            skipped.append(sc.name)
            continue
        per_spp = []
        for p, n in enumerate(spp):
            needs = {"albedo", "normal", "depth"} | ({"reference"} if p == 0 else set())
            per_spp.append(load_sequence(seq_scene, spp=int(n), res=res, needs=needs, seed=p,
                                         ref_spp=ref_spp, cache=cache, progress=False))
        noisy.append(np.stack([[_finite(f.color) for f in s] for s in per_spp]))
        albedo.append(np.stack([[np.clip(_finite(f.albedo), 0, 1) for f in s]
                                for s in per_spp]))
        normal.append(np.stack([[np.clip(_finite(f.normal), -1, 1) for f in s]
                                for s in per_spp]))
        depth.append(np.stack([[normalize_depth(f.depth) for f in s] for s in per_spp]))
        refs.append(np.stack([_finite(f.reference) for f in per_spp[0]]))
        names.append(seq_scene.name)
        if progress:
            print(f"  {seq_scene.name}: {time.perf_counter() - t0:.0f} s so far", flush=True)
    config = {"n_sequences": n_sequences, "n_frames": n_frames, "res": res,
              "spp": list(map(int, spp)), "ref_spp": ref_spp, "family_seed": family_seed,
              "min_mean": min_mean, "skipped_dark": skipped,
              "build_s": round(time.perf_counter() - t0, 1)}
    return SequenceSet(noisy=np.stack(noisy), spp=tuple(int(s) for s in spp),
                       reference=np.stack(refs), albedo=np.stack(albedo),
                       normal=np.stack(normal), depth=np.stack(depth), scenes=names,
                       config=config)


def sample_sequence_batch(ss: SequenceSet, rng: np.random.Generator, batch: int, crop: int,
                          frames: int | None = None, exposure: bool = False
                          ) -> dict[str, np.ndarray]:
    """A batch of crops of ``frames`` consecutive frames (same window in every frame, random
    start frame, spp and flips): arrays (B, F, crop, crop, C) named as in :func:`sample_batch`,
    and (B, F) ``level`` and ``exposure`` (each frame's own auto-exposure when ``exposure``, as
    inference computes it frame by frame)."""
    from ..methods.kernels.hdr_input import autoexposure, noise_level

    s_count, p_count, f_count, h, w, _ = ss.noisy.shape
    frames = f_count if frames is None else frames
    if crop > h or crop > w:
        raise DbenchInputError(f"crop: {crop} exceeds the training frames ({h}x{w})")
    if not 1 <= frames <= f_count:
        raise DbenchInputError(f"frames: expected 1..{f_count}, got {frames}")
    out: dict[str, list] = {k: [] for k in ("noisy", "reference", "albedo", "normal", "depth")}
    levels, exposures = [], []
    for _ in range(batch):
        s, p = int(rng.integers(s_count)), int(rng.integers(p_count))
        f0 = int(rng.integers(f_count - frames + 1))
        y0, x0 = int(rng.integers(h - crop + 1)), int(rng.integers(w - crop + 1))
        fy, fx = bool(rng.integers(2)), bool(rng.integers(2))
        sl = (slice(f0, f0 + frames), slice(y0, y0 + crop), slice(x0, x0 + crop))
        noisy = ss.noisy[s, p][sl]
        e = np.array([autoexposure(f) if exposure else 1.0 for f in noisy], np.float32)
        scale = e[:, None, None, None]
        items = {"noisy": noisy * scale, "reference": ss.reference[s][sl] * scale,
                 "albedo": ss.albedo[s, p][sl], "normal": ss.normal[s, p][sl],
                 "depth": ss.depth[s, p][sl]}
        for k, v in items.items():
            if fy:
                v = v[:, ::-1]
            if fx:
                v = v[:, :, ::-1]
            out[k].append(np.ascontiguousarray(v))
        levels.append(np.full(frames, noise_level(ss.spp[p]), np.float32))
        exposures.append(e)
    result = {k: np.stack(v).astype(np.float32) for k, v in out.items()}
    result["level"] = np.stack(levels)
    result["exposure"] = np.stack(exposures)
    return result


def split_sequences(ss: SequenceSet, n_validation: int) -> tuple[SequenceSet, SequenceSet]:
    """The last ``n_validation`` sequences held out."""
    s = ss.noisy.shape[0]
    if not 0 < n_validation < s:
        raise DbenchInputError(f"n_validation: {n_validation} must leave 1..{s - 1} training "
                               f"sequences of {s}")

    def part(sl: slice) -> SequenceSet:
        return SequenceSet(noisy=ss.noisy[sl], spp=ss.spp, reference=ss.reference[sl],
                           albedo=ss.albedo[sl], normal=ss.normal[sl], depth=ss.depth[sl],
                           scenes=ss.scenes[sl], config={**ss.config, "hash_full": ss.hash})

    return part(slice(0, s - n_validation)), part(slice(s - n_validation, s))
