"""Training sets rendered here from the procedural training scenes, cached, and batches of crops.

``build_training_set`` renders, for each training scene, noisy images at several spp (one
independent seed per spp), the AOV features and a reference, all through
:func:`dbench.datasets.load` and therefore through the content-addressed render cache: a second
build reads everything back. Scenes whose quick probe render is nearly black are skipped (they
would teach nothing) and the next index is used, deterministically.

Arrays of a :class:`TrainingSet` (S scenes, P sample counts, square H = W = res):

* ``noisy`` (S, P, H, W, 3) linear radiance; ``spp`` (P,) the sample counts;
* ``reference`` (S, H, W, 3); ``albedo`` (S, H, W, 3); ``normal`` (S, H, W, 3);
* ``depth`` (S, H, W, 1), already divided by the frame's largest depth (spec/autoencoder.md §1).

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


@dataclass
class TrainingSet:
    noisy: np.ndarray
    spp: tuple[int, ...]
    reference: np.ndarray
    albedo: np.ndarray
    normal: np.ndarray
    depth: np.ndarray
    scenes: list[str]
    config: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.noisy = check_buffer("noisy", self.noisy, (None, len(self.spp), None, None, 3))
        s, _, h, w, _ = self.noisy.shape
        self.reference = check_buffer("reference", self.reference, (s, h, w, 3))
        self.albedo = check_buffer("albedo", self.albedo, (s, h, w, 3))
        self.normal = check_buffer("normal", self.normal, (s, h, w, 3))
        self.depth = check_buffer("depth", self.depth, (s, h, w, 1))
        if len(self.scenes) != s:
            raise DbenchInputError(f"scenes: expected {s} names, got {len(self.scenes)}")

    @property
    def shape(self) -> tuple[int, int, int]:
        s, _, h, w, _ = self.noisy.shape
        return s, h, w

    @property
    def hash(self) -> str:
        """SHA-256 of the arrays (float32 bytes), spp and scene names."""
        d = hashlib.sha256()
        for a in (self.noisy, self.reference, self.albedo, self.normal, self.depth):
            d.update(np.ascontiguousarray(a, np.float32).tobytes())
        d.update(json.dumps({"spp": list(self.spp), "scenes": self.scenes}).encode())
        return d.hexdigest()


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
                       min_mean: float = 0.03, progress: bool = True) -> TrainingSet:
    """Render (or read from the cache) ``n_scenes`` procedural training scenes.

    Noisy images at spp[p] use seed p (independent sample streams); features and reference use
    seed 0. Returns a :class:`TrainingSet`; ``config`` records the settings and render times.
    """
    from .. import datasets

    cache = cache or datasets.Cache()
    noisy, refs, albedo, normal, depth, names, skipped = [], [], [], [], [], [], []
    t0 = time.perf_counter()
    index = 0
    while len(names) < n_scenes:
        sc = training_scene(index, family_seed)
        index += 1
        if probe_mean(sc) < min_mean:
            skipped.append(sc.name)
            continue
        base = datasets.load(sc, spp=int(spp[0]), res=res,
                             needs={"color", "albedo", "normal", "depth", "reference"}, seed=0,
                             ref_spp=ref_spp, cache=cache, progress=False)
        frames = [base.color]
        for p, n in enumerate(spp[1:], start=1):
            frames.append(datasets.load(sc, spp=int(n), res=res, needs={"color"}, seed=p,
                                        cache=cache, progress=False).color)
        noisy.append(np.stack([_finite(f) for f in frames]))
        refs.append(_finite(base.reference))
        albedo.append(np.clip(_finite(base.albedo), 0, 1))
        normal.append(np.clip(_finite(base.normal), -1, 1))
        depth.append(normalize_depth(base.depth))
        names.append(sc.name)
        if progress:
            print(f"  {sc.name}: rendered {base.meta['rendered'] or 'nothing'} "
                  f"({time.perf_counter() - t0:.0f} s so far)", flush=True)
    config = {"n_scenes": n_scenes, "res": res, "spp": list(map(int, spp)),
              "ref_spp": ref_spp, "family_seed": family_seed, "min_mean": min_mean,
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


def sample_batch(ts: TrainingSet, rng: np.random.Generator, batch: int, crop: int,
                 spp_choices: Sequence[int] | None = None) -> dict[str, np.ndarray]:
    """A batch of random crops with random horizontal/vertical flips (whole deep image).

    Returns arrays (B, crop, crop, C): ``noisy``, ``reference``, ``albedo``, ``normal``,
    ``depth``, and ``spp`` (B,). ``spp_choices`` restricts the noisy sample counts.
    """
    s_count, h, w = ts.shape
    if crop > h or crop > w:
        raise DbenchInputError(f"crop: {crop} exceeds the training images ({h}x{w})")
    allowed = [i for i, n in enumerate(ts.spp) if spp_choices is None or n in spp_choices]
    if not allowed:
        raise DbenchInputError(f"spp_choices: none of {spp_choices} in the set's {ts.spp}")
    out: dict[str, list] = {k: [] for k in ("noisy", "reference", "albedo", "normal", "depth")}
    spps = []
    for _ in range(batch):
        s = int(rng.integers(s_count))
        p = allowed[int(rng.integers(len(allowed)))]
        y0 = int(rng.integers(h - crop + 1))
        x0 = int(rng.integers(w - crop + 1))
        fy, fx = bool(rng.integers(2)), bool(rng.integers(2))
        sl = (slice(y0, y0 + crop), slice(x0, x0 + crop))
        items = {"noisy": ts.noisy[s, p][sl], "reference": ts.reference[s][sl],
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
        spps.append(ts.spp[p])
    result = {k: np.stack(v).astype(np.float32) for k, v in out.items()}
    result["spp"] = np.array(spps, np.int64)
    return result
