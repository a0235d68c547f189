"""Procedural scene catalogue: one function a scene, each returning a ``mi.load_dict`` dictionary.

No asset is downloaded: every shape, material and texture is built here. Every film uses a box
reconstruction filter, so each 1-spp pass puts exactly one sample in every pixel
(docs/mitsuba.md §4) and the AOVs are plain pixel-footprint averages.

Emitters get a black BSDF everywhere (the built-in Cornell light included), so the albedo buffer
is 0 on light sources and separates them from the surfaces around them; without that, feature-
guided filters cannot tell a ceiling light from the white ceiling it sits on. The ``emitter``
buffer (dbench/datasets/emitter.py) does not rely on this convention: it tests the emitter
itself.

A :class:`Scene` declares its kind (``steady`` here) and the buffers it can provide; the
harness uses that to skip methods that cannot run and to render only what is needed.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, Callable

import numpy as np

from ...errors import DbenchInputError, UnknownNameError
from .record import _CATALOGUE, Scene, available, not_loaded
from .parts import (camera_dict, ceiling_light, diffuse_bsdf, film_dict, mirror_objects, rect_shape,
                    room_shapes)


def _scene(name: str, description: str, **kw: Any):
    def wrap(build: Callable[[Any, int], dict]) -> Callable[[Any, int], dict]:
        _CATALOGUE[name] = Scene(name=name, kind="steady", description=description, build=build,
                                 **kw)
        return build
    return wrap


def get(name: str | Scene, params: dict[str, str] | None = None) -> Scene:
    """The Scene named ``name``: a catalogue name (``params``: the values of the parameters
    it declares, dbench.datasets.scenes.params), a scene file (``.xml``, ``.py``;
    dbench.datasets.scene_files.load, ``params`` fill its ``$parameters``) or a folder of EXR
    renders (dbench.datasets.folders.load). UnknownNameError lists the catalogue otherwise; a
    DbenchInputError names a scene entry point that failed to load (record.not_loaded)."""
    if isinstance(name, Scene):
        return name
    if name in _CATALOGUE:
        if params:  # the parameters the scene declares (dbench.datasets.scenes.params)
            from .params import bind

            return bind(_CATALOGUE[name], params)
        return _CATALOGUE[name]
    from ..folders import load as folder
    from ..scene_files import load as scene_files

    if scene_files.is_scene_file(name):
        return scene_files.resolve(name, params)
    if folder.is_folder_scene(name):
        if params:
            raise DbenchInputError(f"--scene-param: {name} is a folder of renders; parameters "
                                   f"apply to scene files")
        return folder_scene(name)
    why = not_loaded(name)
    if why:  # a scene entry point that failed to load: its failure, not an unknown name
        raise DbenchInputError(f"scene {name!r}: {why}")
    if any(sep in name for sep in "/" + os.sep) and folder.is_folder_scene(name, any_view=True):
        # DIR/NAME beside renders with NAME no view of them (a typo, one of the files): the
        # folder's reading refuses it naming its views, where the catalogue's would list
        # scenes the user did not mean
        return folder_scene(name)
    raise UnknownNameError(
        f"unknown scene {name!r}; available scenes: {', '.join(available())}; or a Mitsuba "
        f"scene file (.xml), a Python scene file (.py) or a folder of EXR renders") from None


def with_normal_encoding(scene: Scene, encoding: str | None, name: str) -> Scene:
    """``scene`` (given as ``name``) with its normals read as ``encoding`` (``--normal-encoding``
    of run and sweep; None: as found). Only a folder of renders has normals that are not
    dbench's own, signed ones; a scene dbench renders is refused."""
    if encoding is None:
        return scene
    if scene.renders or getattr(scene, "info", None) is None:
        raise DbenchInputError(f"--normal-encoding: {name} is rendered by dbench, whose "
                               f"normals are signed; the option applies to a folder of renders "
                               f"(--scene DIR)")
    from dataclasses import replace

    from ..folders.load import with_normal_encoding as encoded

    key = (str(scene.info.path), scene.info.name, scene.info.fingerprint, encoding)
    if key not in _FOLDERS:  # as folder_scene: one object per content (and encoding)
        info = encoded(scene.info, encoding)
        # the scene's identity follows the folder's fingerprint, which now covers the encoding
        _FOLDERS[key] = replace(scene, info=info,
                                params={**scene.params, "fingerprint": info.fingerprint})
    return _FOLDERS[key]


def folder_scene(path: str) -> Scene:
    """A :class:`FolderScene` for a folder of EXR renders (one per folder content)."""
    from ..folders import load as folder

    info = folder.scan_folder(path)
    key = (str(info.path), info.name, info.fingerprint)
    if key not in _FOLDERS:
        # the same object for the same content, so per-scene caches are shared
        _FOLDERS[key] = FolderScene(
            name=info.name, kind="sequence" if info.frames else "steady",
            description=f"renders read from {info.path} (view {info.name})", build=_no_build,
            provides=frozenset(info.buffers), params={"fingerprint": info.fingerprint},
            ev=float(info.ev), info=info)
    return _FOLDERS[key]


_FOLDERS: dict[tuple, Scene] = {}


def _no_build(mi, res):  # pragma: no cover - a folder is read, never rendered
    raise NotImplementedError("a folder of renders is read, not rendered")


@dataclass(frozen=True, eq=False)
class FolderScene(Scene):
    """Renders read from a folder of EXR files (dbench.datasets.folders.load): nothing is rendered;
    ``info`` (a FolderInfo) says which spp, buffers and size the folder holds."""

    info: Any = None
    renders = False

    def key_dict(self, mi, res) -> dict:
        return {"folder": str(self.info.path), "view": self.info.name,
                "fingerprint": self.info.fingerprint}


# ---------------------------------------------------------------------------------------------
# the catalogue


@_scene("cornell", "diffuse Cornell box lit by a ceiling area light (Mitsuba's built-in)")
def cornell(mi, res: int) -> dict:
    d = mi.cornell_box()
    d["light"]["bsdf"] = diffuse_bsdf((0.0, 0.0, 0.0))
    d["sensor"]["film"] = film_dict(res)
    d["sensor"]["sampler"] = {"type": "independent"}
    return d


@_scene("mirrors", "spheres and a box in front of a mirror back wall and a glossy side wall")
def mirrors(mi, res: int) -> dict:
    d = {"type": "scene",
         "sensor": camera_dict(mi, res, origin=[0, 0, 3.9], target=[0, 0, 0])}
    d.update(room_shapes(mi,
                   back_bsdf={"type": "conductor", "material": "Ag"},
                   right_bsdf={"type": "roughconductor", "material": "Cu", "alpha": 0.08}))
    d["light"] = ceiling_light(mi, 0.3)
    d.update(mirror_objects(mi))
    return d


@_scene("caustic", "a glass sphere casting a caustic on a diffuse floor under a small light",
        max_depth=12)
def caustic(mi, res: int) -> dict:
    T = mi.ScalarTransform4f
    d = {"type": "scene",
         "sensor": camera_dict(mi, res, origin=[0, 0.9, 3.6], target=[0, -0.55, 0])}
    d.update(room_shapes(mi))
    d["light"] = rect_shape(mi, T().translate([-0.45, 0.99, 0.1]).rotate([1, 0, 0], 90).scale(0.12),
                       diffuse_bsdf((0, 0, 0)),
                       {"type": "area", "radiance": {"type": "rgb", "value": [80.0, 72.0, 60.0]}})
    d["glass"] = {"type": "sphere", "center": [0.05, -0.6, 0.1], "radius": 0.4,
                  "bsdf": {"type": "dielectric", "int_ior": 1.5, "ext_ior": 1.0}}
    d["pedestal"] = {"type": "cube",
                     "to_world": T().translate([-0.6, -0.8, -0.5]).scale(0.2),
                     "bsdf": diffuse_bsdf((0.3, 0.5, 0.8))}
    return d


@lru_cache(maxsize=4)
def texture_pattern(size: int = 512) -> np.ndarray:
    """A high-frequency albedo texture: checkers of three sizes, stripes and text, (size, size, 3).

    Deterministic (pure NumPy plus matplotlib's Agg rasteriser for the letters).
    """
    y, x = np.mgrid[0:size, 0:size]
    img = np.empty((size, size, 3), np.float32)
    q = size // 2
    checker_fine = ((x // 8 + y // 8) % 2).astype(np.float32)
    checker_coarse = ((x // 32 + y // 32) % 2).astype(np.float32)
    stripes = (np.sin(2 * np.pi * x / 12.0) > 0).astype(np.float32)
    base = np.where((x < q) & (y < q), checker_fine,
                    np.where((x >= q) & (y < q), stripes, checker_coarse))
    colors_a = np.array([0.85, 0.80, 0.70], np.float32)
    colors_b = np.array([0.08, 0.12, 0.35], np.float32)
    img[:] = colors_b + base[..., None] * (colors_a - colors_b)
    img[q:, q:] = _text_tile(q)
    return img


def _text_tile(size: int) -> np.ndarray:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(1, 1), dpi=size)
    canvas = FigureCanvasAgg(fig)
    ax = fig.add_axes([0, 0, 1, 1])
    ax.set_axis_off()
    ax.set_facecolor("white")
    for row, text in enumerate(("dbench", "ABC 123", "denoise", "MC path")):
        ax.text(0.05, 0.85 - row * 0.24, text, fontsize=size / 9, family="DejaVu Sans",
                weight="bold", transform=ax.transAxes)
    canvas.draw()
    rgba = np.asarray(canvas.buffer_rgba(), dtype=np.float32)[..., :3] / 255.0
    ink = 1.0 - rgba.mean(axis=-1, keepdims=True)
    paper = np.array([0.9, 0.85, 0.6], np.float32)
    red = np.array([0.6, 0.05, 0.05], np.float32)
    return paper + ink * (red - paper)


@_scene("textured", "a high-frequency albedo texture (checkers, stripes, letters) under soft "
        "light", max_depth=6)
def textured(mi, res: int) -> dict:
    T = mi.ScalarTransform4f
    tex = {"type": "bitmap", "bitmap": mi.Bitmap(texture_pattern()), "filter_type": "nearest",
           "raw": True}
    d = {"type": "scene",
         "sensor": camera_dict(mi, res, origin=[0, 1.6, 2.4], target=[0, -0.6, 0], fov=45)}
    d["floor"] = rect_shape(mi, T().translate([0, -1, 0]).rotate([1, 0, 0], -90).scale(1.6),
                       {"type": "diffuse", "reflectance": tex})
    d["wall"] = rect_shape(mi, T().translate([0, 0.6, -1.6]).scale([1.6, 1.6, 1]),
                      {"type": "diffuse", "reflectance": tex})
    d["ball"] = {"type": "sphere", "center": [0.5, -0.6, 0.2], "radius": 0.4,
                 "bsdf": diffuse_bsdf((0.7, 0.7, 0.7))}
    d["sky"] = {"type": "constant", "radiance": {"type": "rgb", "value": [0.25, 0.27, 0.3]}}
    d["light"] = rect_shape(mi, T().translate([-0.5, 1.4, 0.6]).rotate([1, 0, 0], 70).scale(0.8),
                       diffuse_bsdf((0, 0, 0)),
                       {"type": "area", "radiance": {"type": "rgb", "value": [3.0, 2.9, 2.7]}})
    return d


@_scene("fireflies", "a room lit only indirectly by a tiny, very bright emitter hidden behind "
        "a baffle: heavy-tailed noise", max_depth=8)
def fireflies(mi, res: int) -> dict:
    T = mi.ScalarTransform4f
    d = {"type": "scene",
         "sensor": camera_dict(mi, res, origin=[0, 0, 3.9], target=[0, -0.1, 0])}
    d.update(room_shapes(mi))
    # A tiny sphere light above a baffle: it can only reach the room after a bounce on the
    # ceiling, so most paths miss it and the few that find it carry huge radiance. The lamp hangs
    # 0.4 below the ceiling: closer (0.2), the ceiling above it formed a 2-pixel hotspot (100×
    # the image mean) that held 99.9 % of every denoiser's squared error, so RMSE on this scene
    # measured that hotspot instead of the heavy-tailed noise.
    d["lamp"] = {"type": "sphere", "center": [0, 0.6, -0.4], "radius": 0.02,
                 "emitter": {"type": "area", "radiance": {"type": "rgb",
                                                          "value": [1500.0, 1300.0, 1000.0]}}}
    d["baffle"] = {"type": "cube",
                   "to_world": T().translate([0, 0.53, -0.4]).scale([0.5, 0.03, 0.5]),
                   "bsdf": diffuse_bsdf((0.6, 0.6, 0.6))}
    d["ball"] = {"type": "sphere", "center": [-0.4, -0.65, 0.1], "radius": 0.35,
                 "bsdf": diffuse_bsdf((0.8, 0.8, 0.8))}
    d["block"] = {"type": "cube",
                  "to_world": T().translate([0.45, -0.7, -0.3]).rotate([0, 1, 0], -20)
                  .scale([0.25, 0.3, 0.25]),
                  "bsdf": diffuse_bsdf((0.7, 0.7, 0.75))}
    return d
