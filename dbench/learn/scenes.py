"""Procedural training scenes, disjoint from the evaluation catalogue.

``training_scene(i)`` draws scene ``i`` from a random generator seeded by ``i`` (and
``family_seed``): an enclosure (a closed room seen from inside, an open room seen from outside,
both with random wall materials, or a ground plane under a sky), 2 to 6 random objects
(sphere, cube, cylinder, disk, panel) with random materials (diffuse with flat colour,
checkerboard or a procedural bitmap; plastic; rough plastic; smooth and rough conductors; glass),
and 1 to 3 lights (area rectangles facing down, small sphere emitters, spot lights, sky), every
emitter with a black BSDF as in the catalogue. Mirrors and glass are deliberately common: they are the learned methods' weak
spots on the evaluation scenes (seed 001 §3.5).

None of these scenes is registered in :mod:`dbench.datasets.scenes.catalogue`; names are ``train-NNN``,
and the evaluation catalogue (cornell, mirrors, caustic, textured, fireflies) is never used for
training. Textures are made here (NumPy), never the catalogue's ``texture_pattern``.

Every film is square with a box filter (as in the catalogue), so noisy images, AOVs and
references are pixel-aligned averages over the same footprint (docs/methods/nca.md §5 note).

Example:
    >>> sc = training_scene(3)
    >>> sc.name, sc.kind
    ('train-003', 'steady')
"""
from __future__ import annotations

from functools import lru_cache
from typing import Any

import numpy as np

from ..datasets.scenes.catalogue import Scene, camera_dict, diffuse_bsdf, rect_shape

EVALUATION_SCENES = ("cornell", "mirrors", "caustic", "textured", "fireflies")
METALS = ("Ag", "Al", "Au", "Cu", "Cr")


# ---------------------------------------------------------------------------------------------
# procedural textures (different families from the catalogue's checkers/stripes/letters)


@lru_cache(maxsize=64)
def procedural_texture(seed: int, size: int = 128) -> np.ndarray:
    """A (size, size, 3) float32 albedo texture in [0.02, 0.95] drawn from one of four families:
    smooth value noise, a random tile mosaic, polka dots, plaid."""
    rng = np.random.default_rng(seed)
    kind = int(rng.integers(4))
    y, x = np.mgrid[0:size, 0:size].astype(np.float32) / size
    c0, c1 = rng.uniform(0.03, 0.9, 3), rng.uniform(0.03, 0.9, 3)
    if kind == 0:  # smooth value noise, bilinear upsampling of a coarse grid
        g = int(rng.integers(4, 12))
        grid = rng.random((g + 1, g + 1))
        gy, gx = y * g, x * g
        i, j = np.floor(gy).astype(int), np.floor(gx).astype(int)
        fy, fx = gy - i, gx - j
        t = (grid[i, j] * (1 - fy) * (1 - fx) + grid[i + 1, j] * fy * (1 - fx)
             + grid[i, j + 1] * (1 - fy) * fx + grid[i + 1, j + 1] * fy * fx)
    elif kind == 1:  # mosaic of random tiles
        g = int(rng.integers(3, 16))
        tiles = rng.random((g, g))
        t = tiles[np.minimum((y * g).astype(int), g - 1), np.minimum((x * g).astype(int), g - 1)]
    elif kind == 2:  # polka dots
        f = float(rng.uniform(4, 14))
        r = float(rng.uniform(0.15, 0.4))
        t = (((x * f) % 1 - 0.5) ** 2 + ((y * f) % 1 - 0.5) ** 2 < r * r).astype(np.float32)
    else:  # plaid
        fx, fy = rng.uniform(3, 20, 2)
        t = 0.5 * ((np.sin(2 * np.pi * fx * x) > 0.3).astype(np.float32)
                   + (np.sin(2 * np.pi * fy * y) > 0.3).astype(np.float32))
    img = c0 + t[..., None] * (c1 - c0)
    return np.ascontiguousarray(np.clip(img, 0.02, 0.95), dtype=np.float32)


# ---------------------------------------------------------------------------------------------
# random building blocks


def _rgb(rng, lo=0.05, hi=0.9) -> list[float]:
    return [float(v) for v in rng.uniform(lo, hi, 3)]


def _reflectance(mi, rng) -> dict:
    r = rng.random()
    if r < 0.5:
        return {"type": "rgb", "value": _rgb(rng)}
    if r < 0.7:
        s = float(rng.uniform(2, 12))
        return {"type": "checkerboard", "color0": {"type": "rgb", "value": _rgb(rng)},
                "color1": {"type": "rgb", "value": _rgb(rng)},
                "to_uv": mi.ScalarTransform4f().scale([s, s, 1])}
    tex = procedural_texture(int(rng.integers(1 << 30)))
    return {"type": "bitmap", "bitmap": mi.Bitmap(tex), "raw": True,
            "filter_type": "nearest" if rng.random() < 0.5 else "bilinear"}


def _material(mi, rng, allow_glass: bool = True) -> dict:
    r = rng.random()
    if r < 0.40:
        return {"type": "diffuse", "reflectance": _reflectance(mi, rng)}
    if r < 0.52:
        return {"type": "plastic", "diffuse_reflectance": _reflectance(mi, rng),
                "int_ior": float(rng.uniform(1.3, 1.7))}
    if r < 0.62:
        return {"type": "roughplastic", "diffuse_reflectance": _reflectance(mi, rng),
                "alpha": float(rng.uniform(0.05, 0.4))}
    if r < 0.74:
        return {"type": "conductor", "material": str(rng.choice(METALS))}
    if r < 0.86 or not allow_glass:
        return {"type": "roughconductor", "material": str(rng.choice(METALS)),
                "alpha": float(rng.uniform(0.03, 0.35))}
    if r < 0.95:
        return {"type": "dielectric", "int_ior": float(rng.uniform(1.3, 1.8)), "ext_ior": 1.0}
    return {"type": "roughdielectric", "int_ior": float(rng.uniform(1.3, 1.7)),
            "alpha": float(rng.uniform(0.05, 0.3))}


def _object(mi, rng, index: int, z_max: float = 0.6) -> dict:
    T = mi.ScalarTransform4f
    kind = str(rng.choice(["sphere", "cube", "cylinder", "disk", "panel"],
                          p=[0.35, 0.25, 0.2, 0.1, 0.1]))
    pos = [float(rng.uniform(-0.75, 0.75)), float(rng.uniform(-0.95, 0.2)),
           float(rng.uniform(-0.8, z_max))]
    size = float(rng.uniform(0.12, 0.45))
    bsdf = _material(mi, rng)
    angle = float(rng.uniform(0, 360))
    axis = [float(v) for v in rng.normal(size=3)]
    if kind == "sphere":
        pos[1] = max(pos[1], -1 + size)
        return {"type": "sphere", "center": pos, "radius": size, "bsdf": bsdf}
    if kind == "cube":
        return {"type": "cube", "bsdf": bsdf,
                "to_world": T().translate(pos).rotate(axis, angle)
                .scale([size, float(size * rng.uniform(0.4, 1.6)), size])}
    if kind == "cylinder":
        h = float(rng.uniform(0.2, 0.9))
        return {"type": "cylinder", "radius": float(size * 0.6), "bsdf": bsdf,
                "p0": [pos[0], -1.0, pos[2]], "p1": [pos[0], -1.0 + h, pos[2]]}
    if kind == "disk":
        return {"type": "disk", "bsdf": bsdf,
                "to_world": T().translate(pos).rotate(axis, angle).scale(size * 1.3)}
    return {"type": "rectangle", "bsdf": bsdf,
            "to_world": T().translate(pos).rotate(axis, angle).scale([size * 1.5, size, 1])}


def _light(mi, rng, enclosed: bool) -> dict:
    """A random light. Emitters get a black BSDF, as in the evaluation catalogue, so a visible
    light has albedo 0 in the AOV (the convention the networks learn from)."""
    T = mi.ScalarTransform4f
    black = diffuse_bsdf((0, 0, 0))
    color = np.array([1.0, 1.0, 1.0]) + rng.uniform(-0.35, 0.35, 3)
    r = rng.random()
    if r < 0.6:  # area rectangle under the ceiling, facing down (tilted a little)
        size = float(rng.uniform(0.1, 0.45))
        power = float(rng.uniform(6, 25))
        x, z = float(rng.uniform(-0.6, 0.6)), float(rng.uniform(-0.7, 0.4))
        tilt = 90.0 + float(rng.uniform(-20, 20))
        return rect_shape(mi, T().translate([x, 0.98, z]).rotate([1, 0, 0], tilt)
                     .scale([size, float(size * rng.uniform(0.5, 1.5)), 1]), black,
                     {"type": "area", "radiance": {"type": "rgb",
                                                   "value": list(color * power)}})
    if r < 0.8:  # small bright sphere
        rad = float(rng.uniform(0.02, 0.08))
        power = float(rng.uniform(0.5, 3.0)) / (rad * rad)
        return {"type": "sphere", "radius": rad, "bsdf": black,
                "center": [float(rng.uniform(-0.7, 0.7)), float(rng.uniform(0.2, 0.85)),
                           float(rng.uniform(-0.7, 0.3))],
                "emitter": {"type": "area", "radiance": {"type": "rgb",
                                                         "value": list(color * power)}}}
    origin = [float(rng.uniform(-0.8, 0.8)), 0.9, float(rng.uniform(-0.5, 0.9))]
    return {"type": "spot", "cutoff_angle": float(rng.uniform(20, 50)),
            "to_world": T().look_at(origin=origin, target=[float(rng.uniform(-0.5, 0.5)), -1.0,
                                                           float(rng.uniform(-0.5, 0.5))],
                                    up=[0, 0, 1]),
            "intensity": {"type": "rgb", "value": list(color * float(rng.uniform(3, 15)))}}


def _layout(rng) -> tuple[str, list[float], list[float], float]:
    """Enclosure kind, camera origin, target and field of view (the first draws of a training
    scene's generator, shared by :func:`build_training_dict` and :func:`training_sequence`)."""
    kind = str(rng.choice(["closed", "open", "ground"], p=[0.35, 0.35, 0.3]))
    if kind == "closed":  # camera inside a closed room: every pixel sees a surface
        origin = [float(rng.uniform(-0.5, 0.5)), float(rng.uniform(-0.4, 0.6)),
                  float(rng.uniform(0.6, 0.95))]
        fov = float(rng.uniform(50, 75))
    elif kind == "open":  # looking into an open room from outside, the room filling the view
        az = float(rng.uniform(-0.25, 0.25))
        dist = float(rng.uniform(2.6, 3.9))
        origin = [dist * np.sin(az), float(rng.uniform(-0.2, 0.4)), dist * np.cos(az)]
        fov = float(rng.uniform(35, 45))
    else:  # objects on a ground plane under a sky
        az = float(rng.uniform(-0.6, 0.6))
        dist = float(rng.uniform(2.6, 4.2))
        origin = [dist * np.sin(az), float(rng.uniform(0.2, 1.8)), dist * np.cos(az)]
        fov = float(rng.uniform(35, 60))
    target = [float(rng.uniform(-0.3, 0.3)), float(rng.uniform(-0.6, 0.0)),
              float(rng.uniform(-0.5, 0.0))]
    return kind, origin, target, fov


def build_training_dict(mi, res: int, index: int, family_seed: int = 0) -> dict:
    """The ``mi.load_dict`` dictionary of training scene ``index`` at ``res`` px."""
    rng = np.random.default_rng([family_seed, index, 1234])
    T = mi.ScalarTransform4f
    kind, origin, target, fov = _layout(rng)
    enclosed = kind != "ground"
    d: dict[str, Any] = {"type": "scene"}
    d["sensor"] = camera_dict(mi, res, origin=origin, target=target, fov=fov)
    if enclosed:
        walls = {"floor": T().translate([0, -1, 0]).rotate([1, 0, 0], -90),
                 "ceiling": T().translate([0, 1, 0]).rotate([1, 0, 0], 90),
                 "back": T().translate([0, 0, -1]),
                 "left": T().translate([-1, 0, 0]).rotate([0, 1, 0], 90),
                 "right": T().translate([1, 0, 0]).rotate([0, 1, 0], -90)}
        if kind == "closed":
            walls["front"] = T().translate([0, 0, 1]).rotate([0, 1, 0], 180)
        for name, tw in walls.items():
            if name in ("left", "right", "back") and rng.random() < 0.15:
                bsdf = _material(mi, rng, allow_glass=False)
            else:
                bsdf = {"type": "diffuse", "reflectance": (
                    _reflectance(mi, rng) if rng.random() < 0.4 else
                    {"type": "rgb", "value": _rgb(rng, 0.1, 0.85)})}
            d[f"wall_{name}"] = rect_shape(mi, tw.scale(1.0), bsdf)
    else:
        d["ground"] = rect_shape(mi, T().translate([0, -1, 0]).rotate([1, 0, 0], -90).scale(4.0),
                            {"type": "diffuse", "reflectance": _reflectance(mi, rng)})
        sky = np.array([0.5, 0.6, 0.8]) * float(rng.uniform(0.1, 1.0))
        d["sky"] = {"type": "constant", "radiance": {"type": "rgb", "value": list(sky)}}
    for i in range(int(rng.integers(2, 7))):
        d[f"object{i}"] = _object(mi, rng, i, z_max=0.3 if kind == "closed" else 0.6)
    for i in range(int(rng.integers(1, 4)) if enclosed else int(rng.integers(0, 3))):
        d[f"light{i}"] = _light(mi, rng, enclosed)
    if enclosed and not any(k.startswith("light") for k in d):
        d["light0"] = _light(mi, rng, enclosed)
    return d


def training_scene(index: int, family_seed: int = 0) -> Scene:
    """Training scene ``index`` (deterministic in ``index`` and ``family_seed``)."""
    rng = np.random.default_rng([family_seed, index, 99])
    max_depth = int(rng.choice([6, 8, 10]))

    def build(mi, res: int) -> dict:
        return build_training_dict(mi, res, index, family_seed)

    return Scene(name=f"train-{index:03d}", kind="steady",
                 description=f"procedural training scene {index} (family {family_seed})",
                 build=build, max_depth=max_depth,
                 params={"training_index": index, "family_seed": family_seed})


def training_sequence(index: int, n_frames: int = 8, family_seed: int = 0):
    """Training scene ``index`` as a camera animation (a :class:`~dbench.datasets.sequence.load.
    SequenceScene` named ``train-seq-NNN``, not registered): the geometry and lights of
    :func:`training_scene`, the camera turning about its target by a random 0.5-1.5 degrees per
    frame (either way) and drifting up or down a little, so the recurrent autoencoder sees
    moving content, disocclusions and the matched 1-spp G-buffer of the temporal datasets.

    Example:
        >>> seq = training_sequence(3)
        >>> seq.name, seq.kind, seq.n_frames
        ('train-seq-003', 'sequence', 8)
    """
    from ..datasets.sequence.scene import SEQUENCE_BUFFERS, SequenceScene

    kind, origin, target, fov = _layout(np.random.default_rng([family_seed, index, 1234]))
    motion = np.random.default_rng([family_seed, index, 777])
    step = np.radians(float(motion.uniform(0.5, 1.5)) * float(motion.choice([-1.0, 1.0])))
    rise = float(motion.uniform(-0.01, 0.01))
    max_depth = training_scene(index, family_seed).max_depth
    o, t = np.asarray(origin, float), np.asarray(target, float)
    limit = 0.95 if kind == "closed" else np.inf  # stay inside a closed room

    def camera(i: int) -> tuple:
        a = step * i
        dx, dz = o[0] - t[0], o[2] - t[2]
        x = t[0] + dx * np.cos(a) + dz * np.sin(a)
        z = t[2] - dx * np.sin(a) + dz * np.cos(a)
        pos = np.clip([x, o[1] + rise * i, z], -limit, limit)
        return tuple(float(v) for v in pos), tuple(float(v) for v in t)

    def geometry(mi) -> dict:
        d = build_training_dict(mi, 16, index, family_seed)
        d.pop("sensor")
        d.pop("type")
        return d

    def build(mi, res: int) -> dict:
        return seq.frame_dict(mi, res, 0)

    seq = SequenceScene(name=f"train-seq-{index:03d}", kind="sequence",
                        description=f"procedural training sequence {index} "
                                    f"(family {family_seed})",
                        build=build, provides=SEQUENCE_BUFFERS, max_depth=max_depth,
                        params={"training_index": index, "family_seed": family_seed,
                                "sequence": True},
                        n_frames=n_frames, geometry=geometry, camera=camera,
                        lights=lambda i: {}, fov=fov)
    return seq
