"""Scenes from files: ``--scene PATH.xml`` (Mitsuba 3) and ``--scene PATH.py`` (Python).

**Mitsuba XML** (README.md, "Mitsuba scene files"). The file is read with Mitsuba's own
parser and loaded once as ``mi.load_file(path, **params)`` loads it (``$name`` parameters from
``--scene-param name=value``; relative asset paths resolve against the file's folder;
:mod:`dbench.datasets.scene_files.xml`). dbench keeps the scene's shapes (``shapegroup``s with their
``instance``s), materials, media and emitters (the loaded objects themselves) and takes over
what it must control:

- the film: ``hdrfilm`` of the requested size, box reconstruction filter (every 1-spp pass puts
  one sample in each pixel), the whole view (a crop window of the file's film is not applied,
  and the record says so);
- the camera: a ``perspective`` (or ``thinlens``) camera with the file's ``to_world``, clip
  planes and principal point; the file's field of view is kept along the smaller image side, so
  the file's own film size reproduces its view exactly and any other size widens it along the
  longer side (dbench.resolution);
- the sampler (``independent``, dbench's seeds); the integrator is the file's with its settings
  wherever they are set (``-1``: unlimited), wrappers (``moment``, ``aov``, ``stokes``)
  unwrapped, replaced by ``path`` only where it cannot give one sample per pixel and pass
  (:mod:`dbench.datasets.scene_files.integrator`); the AOV and emitter passes are dbench's own.

Spectral and polarized files render in the RGB variant with their conversions stated, or are
refused naming the construct (:mod:`dbench.datasets.scene_files.rgb`). Every steady frame of a file
carries how its render differs from the file in ``frame.meta["scene_file"]`` and, as report
lines, ``frame.meta["scene_file_settings"]`` (:mod:`dbench.datasets.scene_files.fidelity`).
A scene without an emitter (XML or Python) is refused before anything renders: its images are
black, and every method would match them perfectly.

The cache key covers the file's bytes, the bytes of every file it references (``filename``
strings, ``<include>`` fragments and ``<spectrum filename>``s, found as Mitsuba finds them:
after ``<path>`` elements and ``$parameter`` substitution, fragments' names relative to the
scene's folder; :mod:`dbench.datasets.scene_files.assets`), the parameters, the integrator dbench
renders with (its type and settings) and the requested size, so editing the scene, a fragment
or a texture invalidates exactly its entries (README.md, "Your scene, your renders, any size").
A referenced file that cannot be found is refused before anything renders, naming it and the
folders searched.

**Python files**. ``build(mi, width, height) -> dict`` (or ``build(mi, res)``,
:mod:`dbench.datasets.scenes.build`) returns a ``mi.load_dict`` dictionary with a sensor (dbench
replaces its film and sampler as for XML; a ``fov`` is read along x as in Mitsuba's default,
a ``focal_length``, or neither, as the fov along x Mitsuba makes of it:
:func:`dbench.resolution.focal_fov`).
A steady file renders its dictionary's ``"integrator"`` by the rules of XML files (kept,
unwrapped, or replaced by ``path`` with the reason; none: ``path``, max_depth 8;
:func:`dbench.datasets.scene_files.integrator.plan_dict`), and its frames carry the same
``meta["scene_file"]`` record (:func:`dbench.datasets.scene_files.fidelity.dict_record`).
The dictionary is loaded once at 8 px when the file is resolved, so a type Mitsuba has no
plugin for is refused before anything renders; ``sys.exit`` in the file or in ``build`` is
refused too (exit 2), never the file's own exit code, and so is ``mi.set_variant`` there
(:func:`dbench.datasets.scenes.build.keeps_variant`). Optional module attributes, each
checked when the file is resolved and refused in one line naming it where it is not of its
kind (:mod:`dbench.datasets.scene_files.attributes`):

- ``kind``: ``"steady"`` (default), ``"sequence"`` or ``"transient"``;
- ``max_depth`` (overrides the depth of the integrator that renders, as the record says;
  else the dictionary integrator's, else 8), ``ev`` (exposure of the tone map), ``description``;
- sequences: ``camera(i) -> (origin, target)`` per frame (required), ``lights(i) ->
  {shape key: (r, g, b)}`` (radiance of emitting shapes per frame), ``frames`` (default 24);
  both functions are called for every frame when the file is resolved, and checked;
  the geometry is ``build``'s dictionary without its sensor and integrator, and each frame
  is seen at ``camera(i)`` through a perspective camera of the sensor's ``fov`` (or
  ``focal_length``, as for steady files; :func:`dbench.datasets.scene_files.attributes.sequence_fov`);
- sequence and transient scenes render with dbench's integrators (``path``; the transient one),
  so a dictionary integrator other than a ``path`` (``volpath`` for ``transient_prbvolpath``)
  setting at most ``max_depth`` is refused, naming it;
- transient scenes: ``window_start`` and ``window_end`` (optical path length in metres,
  required; :func:`dbench.datasets.transient.load.size_window` measures them), ``bins`` (default
  200), ``integrator`` (``transient_path``, or ``transient_prbvolpath`` for media).

The cache key of a Python scene is its dictionary (as for the catalogue) plus the file's bytes;
the dictionary's ``"filename"`` strings are keyed by the bytes of the files they name
(:mod:`dbench.datasets.file_refs`), and objects ``build`` loaded itself by their parameters
(:func:`dbench.datasets.cache.canonical`), so an edited texture or mesh renders afresh.

Example:
    >>> sc = resolve("my/scene.xml", {"spp": "16"})                 # doctest: +SKIP
    >>> datasets.load(sc, spp=4, res="160x90").color.shape           # doctest: +SKIP
    (90, 160, 3)
"""
from __future__ import annotations

import hashlib
import importlib.machinery
import importlib.util
import math
import re
from copy import deepcopy
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import DbenchInputError
from ...resolution import Res, parse_res
from ..mitsuba_env import focus, mitsuba, scene_cache
from ..scenes.record import STEADY_BUFFERS, Scene
from ..scenes.build import (call_build, check_lit, check_same_build, exit_message,
                            integrator_settings, keeps_variant, probe_load)
from ..scenes.build import own_camera as _own_camera
from .assets import asset_hashes as _sources, scene_walk
from .attributes import sequence_fov, sequence_functions, settings
from ..cache import referenced
from ..scenes.parts import film_dict
from .finite import check_dictionary, check_state
from .fidelity import FILTER, dict_record, file_crop, record, report_lines
from .integrator import DEFAULT_MAX_DEPTH, plan as _integrator_plan, plan_dict
from .rgb import rgb_notes
from .xml import children, load as _load_xml, parse as _parse_xml, shape_groups, where

#: Part of every file scene's cache key; change it when the translation above changes.
FILE_SCENE_VERSION = "file-scene-3"
SUFFIXES = (".xml", ".py")
_CAMERAS = {"PerspectiveCamera": "perspective", "ThinLensCamera": "thinlens"}


def is_scene_file(text: str) -> bool:
    """Whether ``text`` names a scene file (ends in .xml or .py), existing or not."""
    return str(text).lower().endswith(SUFFIXES)


def parse_scene_params(items) -> dict[str, str]:
    """``["key=value", ...]`` (``--scene-param``) → {key: value}; DbenchInputError otherwise."""
    out: dict[str, str] = {}
    for item in items or []:
        key, sep, value = str(item).partition("=")
        if not sep or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", key.strip()):
            raise DbenchInputError(f"--scene-param: expected NAME=VALUE, got {item!r}")
        key = key.strip()
        _check_finite(key, value)
        if key in out and out[key] != value:  # the last would win without a word
            raise DbenchInputError(f"--scene-param: {key} given twice, {out[key]!r} and "
                                   f"{value!r}; give it once")
        out[key] = value
    return out


def _check_finite(key: str, value: str) -> None:
    """Refuse a value holding a number that is not finite (``nan``, ``inf``, ``1e400``, in
    a list such as ``1,nan,2`` too): Mitsuba takes it, and a light of NaN radiance renders a
    black image that every method then matches perfectly."""
    for token in re.split(r"[\s,]+", value.strip()):
        try:
            number = float(token)
        except ValueError:
            continue  # not a number: a name, a file, a colour word
        if not math.isfinite(number):
            raise DbenchInputError(f"--scene-param {key}={value}: {token!r} is not a finite "
                                   f"number")


def resolve(path: str | Path, params: dict[str, str] | None = None) -> Scene:
    """The :class:`Scene` of a scene file, the same object for the same file content and
    parameters (renders of it share the in-process scene caches). DbenchInputError, naming the
    file, when it does not exist, has another suffix or does not load."""
    p = Path(path).expanduser()
    if not p.is_file():
        raise DbenchInputError(f"--scene {path}: no such file (scene files end in "
                               f"{' or '.join(SUFFIXES)})")
    p = p.resolve()
    params = {str(k): str(v) for k, v in (params or {}).items()}
    suffix = p.suffix.lower()
    if suffix not in SUFFIXES:
        raise DbenchInputError(f"--scene {path}: unknown scene file type {suffix!r}; "
                               f"expected {' or '.join(SUFFIXES)}")
    if suffix == ".py" and params:
        raise DbenchInputError(f"--scene-param: {p.name} is a Python scene; parameters apply "
                               f"to XML scenes (set them in the file)")
    if suffix == ".xml":
        # the digest covers every file the scene reads, so an edited texture loads afresh
        sources, defaults = scene_walk(str(p), params)
        # a value the file's own <default> gives is no parameter: the same scene, the same key
        params = {k: v for k, v in params.items() if defaults.get(k) != v}
        digest = _sha256(repr(sorted(sources.items())).encode())
        return _xml_scene(str(p), tuple(sorted(params.items())), digest)
    digest = _sha256(p.read_bytes())
    # one object per content of the files its dictionary names too: the renders' in-process
    # caches are keyed by the object, and an edited texture must not be served from them
    files = referenced(_built(_module(str(p), digest), str(p), mitsuba(), 8))
    return _python_scene(str(p), files, digest)


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


# ---------------------------------------------------------------------------------------------
# Mitsuba XML


@dataclass(frozen=True, eq=False)
class XmlScene(Scene):
    """A steady scene read from a Mitsuba XML file (module docstring)."""

    path: str = ""
    file_params: tuple = ()
    #: what the scene is called in its identity (dbench.datasets._base_description): not the
    #: file's name, which a copy may change
    identity_name: str = "(scene file)"
    # integrator_plan (dbench.datasets.scene_files.integrator) and frame_meta
    # (dbench.datasets.scene_files.fidelity) are Scene's, always set for a file

    def objects_key(self) -> tuple:
        # the key _xml_scene focused on before loading the file's objects: a load of this
        # scene keeps them instead of loading the file again
        return _file_key(self.path, self.file_params, self.params["sha256"])

    def key_dict(self, mi, res) -> dict:
        # neither the file's path nor its name: the sources hold every file's bytes, so the
        # same scene tree anywhere on disk, under any name, is the same scene
        return {"loader": FILE_SCENE_VERSION,
                "res": parse_res(res).key,
                "sources": _sources(self.path, dict(self.file_params)),
                "params": dict(self.file_params), "max_depth": self.max_depth,
                "integrator": self.integrator_plan.render, "filter": FILTER}

    def scene_dict(self, mi, res) -> dict:
        res = parse_res(res)
        loaded = _loaded_xml(self.path, self.file_params, mi.variant(), self.params["sha256"])
        d: dict[str, Any] = {"type": "scene", "sensor": _sensor_dict(mi, loaded, res, self.path),
                             "integrator": deepcopy(self.integrator_plan.render)}
        # the instances' groups go in too: without them Mitsuba cannot build the instances
        for i, group in enumerate(shape_groups(loaded)):
            d[f"group{i:05d}"] = group
        for i, shape in enumerate(loaded.shapes()):
            d[f"shape{i:05d}"] = shape
        # area lights come with their shapes; environment, point, spot and directional
        # emitters have no shape and are added themselves
        free = [e for e in loaded.emitters() if e.get_shape() is None]
        for i, emitter in enumerate(free):
            d[f"emitter{i:03d}"] = emitter
        return d


def _file_key(path: str, params: tuple, digest: str) -> tuple:
    """The scene file's identity for :func:`dbench.datasets.mitsuba_env.focus`."""
    return ("scene file", path, params, digest)


@lru_cache(maxsize=32)
def _xml_scene(path: str, params: tuple, digest: str) -> XmlScene:
    mi = mitsuba()
    state = _parse_xml(path, dict(params))
    check_state(state, path)  # a NaN would render as 0 in dbench's sums (finite.py)
    # constructs with no RGB form are refused before any object of the file exists
    conversions = rgb_notes(state, path)
    integrator = _integrator_plan(state, path)
    _check_camera(mi, state, path)  # before the load: a large scene takes minutes to load
    focus(_file_key(path, params, digest))  # its objects are checked by rendering (check_lit)
    loaded = _loaded_xml(path, params, mi.variant(), digest)
    sensor = _sensor_dict(mi, loaded, parse_res(8), path)  # refuses unsupported cameras
    check_lit(loaded, f"--scene {path}")  # a black image every method would match
    film = loaded.sensors()[0].film()
    rec = record(integrator, state, sensor["type"], conversions,
                 tuple(int(v) for v in film.size()), len(loaded.sensors()), file_crop(film))
    name = Path(path).name
    return XmlScene(name=name, kind="steady", description=f"Mitsuba scene file {path}",
                    build=_no_build, max_depth=integrator.max_depth, provides=STEADY_BUFFERS,
                    params={"sha256": digest, "file_params": dict(params)}, path=path,
                    file_params=params, integrator_plan=integrator,
                    frame_meta={"scene_file": rec, "scene_file_settings": report_lines(rec),
                                # the --scene-param values, which reports state beside them
                                **({"scene_params": dict(params)} if params else {})})


def _check_camera(mi, state, path: str) -> None:
    """Refuse, from the parse alone, a file whose first sensor is no camera dbench renders
    through (:func:`_sensor_dict` checks the loaded one too, and a file without a sensor):
    loading it first cost the whole load, and a sensor that warns while it is built (an
    irradiance meter with the film's gaussian filter) added Mitsuba's line to the refusal."""
    sensors = children(state, state.root, mi.ObjectType.Sensor)
    name = sensors[0][1].props.plugin_name() if sensors else None
    if name is not None and name not in _CAMERAS.values():
        raise DbenchInputError(f"--scene {path}: sensor {name} at {where(state, sensors[0][1])} "
                               f"is not supported; use a perspective or thinlens camera")


def file_film_size(scene: XmlScene) -> tuple[int, int]:
    """(width, height) of the film the XML file itself declares."""
    mi = mitsuba()
    loaded = _loaded_xml(scene.path, scene.file_params, mi.variant(), scene.params["sha256"])
    w, h = (int(v) for v in loaded.sensors()[0].film().size())
    return w, h


def _no_build(mi, res):  # pragma: no cover - XmlScene overrides scene_dict
    raise NotImplementedError


@scene_cache()
def _loaded_xml(path: str, params: tuple, variant: str, digest: str):
    """The file's objects, loaded as ``mi.load_file`` loads them but for its integrator
    (dbench.datasets.scene_files.xml; ``digest`` keys the cache on its content). Mitsuba puts the
    file's folder first in the resolver of this load itself; the process's resolver is left as
    it is, so one scene's folder never supplies another scene's assets."""
    return _load_xml(path, dict(params))


def _sensor_dict(mi, loaded, res: Res, path: str) -> dict:
    """dbench's camera for the file's first sensor (module docstring): its kind, pose, clip
    planes and principal point, the field of view along the smaller side, dbench's film and
    sampler."""
    sensors = loaded.sensors()
    if not sensors:
        raise DbenchInputError(f"--scene {path}: the file has no <sensor>; dbench renders "
                               f"through the scene's camera")
    sensor = sensors[0]
    kind = _CAMERAS.get(sensor.class_name())
    if kind is None:
        raise DbenchInputError(f"--scene {path}: sensor {sensor.class_name()} is not "
                               f"supported; use a perspective or thinlens camera")
    p = mi.traverse(sensor)
    film_w, film_h = (int(v) for v in sensor.film().size())
    x_fov = float(np.ravel(p["x_fov"])[0])
    tan_x = math.tan(math.radians(x_fov) / 2.0)
    # the angle along the file film's smaller side, which "smaller" keeps at any size
    small = x_fov if film_w <= film_h else math.degrees(2.0 * math.atan(tan_x * film_h / film_w))
    matrix = np.array(p["to_world"].matrix, dtype=np.float64).reshape(4, 4)
    d: dict[str, Any] = {"type": kind, "fov": small, "fov_axis": "smaller",
                         "to_world": mi.ScalarTransform4f(matrix),
                         "near_clip": float(np.ravel(p["near_clip"])[0]),
                         "far_clip": float(np.ravel(p["far_clip"])[0]),
                         "film": film_dict(res), "sampler": {"type": "independent"}}
    for key in ("principal_point_offset_x", "principal_point_offset_y", "aperture_radius",
                "focus_distance"):
        if key in p:
            d[key] = float(np.ravel(p[key])[0])
    medium = sensor.get_medium()
    if medium is not None:
        d["medium"] = medium
    return d


# ---------------------------------------------------------------------------------------------
# Python files


@lru_cache(maxsize=32)
def _module(path: str, digest: str):
    name = f"dbench_scene_{digest[:12]}"
    # a loader of its own: the suffix is matched in any case (SUFFIXES), and importlib finds
    # no loader for "scene.PY" (spec None: an internal error)
    spec = importlib.util.spec_from_file_location(
        name, path, loader=importlib.machinery.SourceFileLoader(name, path))
    module = importlib.util.module_from_spec(spec)
    try:
        with keeps_variant(mitsuba(), f"--scene {path}", "the file"):
            spec.loader.exec_module(module)
    except DbenchInputError:
        raise
    except SystemExit as exc:  # a scene file never ends dbench, nor lends it its exit code
        raise DbenchInputError(f"--scene {path}: the file called {exit_message(exc)} while "
                               f"loading; a scene file defines build(mi, width, height) -> dict "
                               f"and must not end the process") from None
    except Exception as exc:
        raise DbenchInputError(f"--scene {path}: the file failed to run: "
                               f"{type(exc).__name__}: {exc}") from None
    if not callable(getattr(module, "build", None)):
        raise DbenchInputError(f"--scene {path}: defines no build(mi, width, height) -> dict")
    return module


def _current(d: dict, files: tuple, path: str) -> dict:
    """``d``, refused where the files it names are no longer the ones its scene was resolved
    with (an object held across an edit would key new renders by the new bytes and render
    the old ones from the in-process caches)."""
    if referenced(d) != files:
        raise DbenchInputError(f"--scene {path}: a file the scene names by \"filename\" (or an "
                               f"object its build loads) changed after the scene was resolved; "
                               f"resolve it again")
    return d


def _built(module, path: str, mi, res) -> dict:
    res = parse_res(res)
    try:
        # either signature (dbench.datasets.scenes.build); sys.exit becomes a DbenchInputError
        d = call_build(module.build, mi, res, f"--scene {path}")
    except DbenchInputError:
        raise
    except Exception as exc:
        raise DbenchInputError(f"--scene {path}: build(mi, {res.width}, {res.height}) failed: "
                               f"{type(exc).__name__}: {exc}") from None
    if not isinstance(d, dict) or not isinstance(d.get("sensor"), dict):
        raise DbenchInputError(f"--scene {path}: build() must return a mi.load_dict dictionary "
                               f"with a 'sensor' dictionary")
    return d


@lru_cache(maxsize=32)
def _python_scene(path: str, files: tuple, digest: str) -> Scene:
    """The scene of the Python file at ``path`` (bytes ``digest``) whose dictionary names the
    files ``files`` ((name, sha256), dbench.datasets.cache.referenced; () before they are
    known)."""
    mi = mitsuba()
    module = _module(path, digest)
    # every module attribute checked before anything is built or rendered (attributes.py)
    attrs = settings(module, path)
    kind, depth = attrs["kind"], attrs["max_depth"]
    probe = _built(module, path, mi, 8)
    check_same_build(probe, _built(module, path, mi, 8), f"--scene {path}", "build(mi, 8, 8)")
    check_dictionary(probe, path)  # a NaN would render as 0 in dbench's sums (finite.py)
    loaded = probe_load(mi, probe, f"--scene {path}", "build()'s dictionary")
    common = dict(name=Path(path).name, kind=kind,
                  description=getattr(module, "description", f"Python scene file {path}"),
                  params={"sha256": digest, **({"files": dict(files)} if files else {})},
                  ev=attrs["ev"])

    def build(mi, res):
        return _own_camera(_current(_built(module, path, mi, res), files, path), res)

    if kind != "sequence" or not callable(getattr(module, "lights", None)):
        check_lit(loaded, f"--scene {path}")  # a black image every method would match
    if kind == "steady":
        # the dictionary's integrator, by the rules of XML files (scene_files.integrator)
        plan = plan_dict(probe.get("integrator"), path, depth)
        rec = dict_record(plan, probe)
        return Scene(build=build, max_depth=plan.max_depth, integrator_plan=plan,
                     frame_meta={"scene_file": rec, "scene_file_settings": report_lines(rec)},
                     **common)
    integrator = probe.get("integrator")
    given = (integrator if isinstance(integrator, dict) else {}).get("max_depth")
    if depth is not None and given is not None and given != depth:  # no record states which
        raise DbenchInputError(f"--scene {path}: max_depth {depth} in the module and "
                               f"{given} in build()'s integrator; give one")
    common["max_depth"] = int(depth if depth is not None else given or DEFAULT_MAX_DEPTH)
    if kind == "sequence":
        _own_integrator_only(integrator, path, kind, "path", "path")
        return _python_sequence(module, path, probe, common, build, attrs["frames"],
                                len(loaded.emitters()))
    own = attrs["integrator"]
    _own_integrator_only(integrator, path, kind, "volpath" if "volpath" in own else "path",
                         own)
    return _python_transient(build, common, attrs)


def _own_integrator_only(integrator, path: str, kind: str, steady: str, renders: str) -> None:
    """Refuse a dictionary integrator that a sequence or transient scene would not render:
    they render with dbench's own integrators (``renders``; ``steady``: the one of its steady
    passes), taking over only the dictionary's ``max_depth``."""
    if integrator is None:
        return
    name, extra = integrator_settings(integrator)
    if name == steady and not extra:
        return
    what = f"integrator {name}" if name != steady else f"{', '.join(extra)} on its {name}"
    raise DbenchInputError(
        f"--scene {path}: build()'s dictionary sets {what}, which a {kind} scene does not "
        f"render: it renders with dbench's {renders}"
        + (f" ({steady} for its steady passes)" if renders != steady else "")
        + f", taking only max_depth from the dictionary; remove the dictionary's integrator or "
        f"make it {{\"type\": \"{steady}\", \"max_depth\": N}}")


def _python_sequence(module, path: str, probe: dict, common: dict, build,
                     frames: int, emitters: int) -> Scene:
    from ..sequence.scene import SEQUENCE_BUFFERS, SequenceScene

    if not callable(getattr(module, "camera", None)):
        raise DbenchInputError(f"--scene {path}: a sequence scene needs camera(i) -> "
                               f"(origin, target)")
    camera, lights = sequence_functions(module, path, frames, probe, emitters)

    def geometry(mi):
        d = build(mi, parse_res(8))
        return {k: v for k, v in d.items() if k not in ("type", "sensor", "integrator")}

    fov = sequence_fov(probe["sensor"], path)
    return SequenceScene(build=build,
                         provides=SEQUENCE_BUFFERS, n_frames=frames,
                         geometry=geometry, camera=camera, lights=lights, fov=fov,
                         **common)


def _python_transient(build, common: dict, attrs: dict) -> Scene:
    from ..transient.scene import TRANSIENT_BUFFERS, TransientScene

    integrator = attrs["integrator"]
    return TransientScene(build=build, provides=TRANSIENT_BUFFERS,
                          window_start=attrs["window_start"], window_end=attrs["window_end"],
                          default_bins=attrs["bins"], integrator=integrator,
                          steady_integrator="volpath" if "volpath" in integrator else "path",
                          **common)


__all__ = ["XmlScene", "resolve", "is_scene_file", "parse_scene_params", "FILE_SCENE_VERSION"]
