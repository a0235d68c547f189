"""The optional module attributes of a Python scene file, checked when the file is resolved
(README.md, "Python scene files"; :mod:`dbench.datasets.scene_files.load` lists them).

Each is a value of a stated kind, or the file is refused in one line naming the attribute,
the value and what it may be (exit 2), before anything renders: a value that is not a number
used to end in an internal error, and a fractional count (``frames = 2.7``, ``bins = 2.5``) was
cut to an integer without a word. A sequence's ``camera(i)`` and ``lights(i)`` are called for
every frame at the same time (:func:`sequence_functions`): a camera looking straight up or
down has no defined roll (``look_at`` with up +y gives NaN) and rendered a black sequence.
"""
from __future__ import annotations

import math
from numbers import Integral, Real
from typing import Any

import numpy as np

from ...data import MAX_COUNT
from ...errors import DbenchInputError
from ...metrics.tonemapping import EV_RANGE, check_ev
from ...resolution import focal_fov
from ..scenes.build import check_same_build

KINDS = ("steady", "sequence", "transient")
#: mitransient's integrators a transient scene file may name
TRANSIENT_INTEGRATORS = ("transient_path", "transient_prbvolpath")
_MISSING = object()


def settings(module, path: str) -> dict[str, Any]:
    """{attribute: checked value} of the attributes ``module`` sets, defaults for those of its
    kind it leaves out (``frames`` 24, ``bins`` 200, ``integrator`` ``transient_path``);
    DbenchInputError naming the first that is not what it may be."""
    def get(name):
        return getattr(module, name, _MISSING)

    kind = get("kind")
    kind = "steady" if kind is _MISSING else kind
    if kind not in KINDS:
        _refuse(path, "kind", kind, f"one of {', '.join(KINDS)}")
    out: dict[str, Any] = {"kind": kind}
    ev = get("ev")
    out["ev"] = 0.0 if ev is _MISSING else _number(path, "ev", ev, "exposure in stops")
    try:  # the tone map's own range (2^ev overflows or rounds to 0 beyond it)
        check_ev(out["ev"])
    except DbenchInputError:
        _refuse(path, "ev", ev, f"a number of stops in [{EV_RANGE[0]}, {EV_RANGE[1]}]")
    depth = get("max_depth")
    if depth is not _MISSING and depth is not None:
        if isinstance(depth, bool) or not isinstance(depth, Integral):
            _refuse(path, "max_depth", depth, "an integer")
        depth = int(depth)
    out["max_depth"] = None if depth is _MISSING else depth
    if kind == "sequence":
        out["frames"] = _count(path, "frames", get("frames"), 24)
    if kind == "transient":
        out["bins"] = _count(path, "bins", get("bins"), 200)
        integrator = get("integrator")
        integrator = "transient_path" if integrator is _MISSING else integrator
        if integrator not in TRANSIENT_INTEGRATORS:
            _refuse(path, "integrator", integrator, " or ".join(TRANSIENT_INTEGRATORS))
        out["integrator"] = integrator
        missing = [a for a in ("window_start", "window_end") if get(a) is _MISSING]
        if missing:
            raise DbenchInputError(
                f"--scene {path}: a transient scene needs {', '.join(missing)} (optical path "
                f"length in metres; dbench.datasets.transient.load.size_window measures them)")
        for name in ("window_start", "window_end"):
            out[name] = _number(path, name, get(name), "optical path length in metres")
        if out["window_end"] <= out["window_start"]:
            _refuse(path, "window_end", out["window_end"],
                    f"a length greater than window_start ({out['window_start']})")
    return out


def sequence_functions(module, path: str, frames: int, shapes: dict, emitters: int = 1):
    """(camera, lights) of a sequence file: its ``camera(i)`` and ``lights(i)`` (none: no
    light changes), each called for every frame now, so that one that raises or returns what
    a frame cannot use is refused naming the frame before anything renders, and wrapped so
    that every later call is checked alike. ``shapes``: build()'s dictionary, whose shape
    keys ``lights`` may name; ``emitters``: the emitters that dictionary holds itself. A
    radiance must be three finite numbers >= 0, and some frame must have an emitter (else every
    image is black and every method would score perfectly, as check_lit refuses for other
    scenes, here before the renders). The values pass on as the file gives them (they are part
    of the frames' dictionaries, and so of their identity)."""
    camera_fn = module.camera
    lights_fn = getattr(module, "lights", None) or (lambda i: {})

    def camera(i: int):
        got = _call(path, "camera", camera_fn, i)
        try:
            origin, target = (np.asarray(v, np.float64).reshape(3) for v in got)
        except (TypeError, ValueError):
            _refuse(path, f"camera({i})", got, "(origin, target), two points (x, y, z)",
                    "returned")
        view = target - origin
        if not (np.isfinite(origin).all() and np.isfinite(target).all()) \
                or np.linalg.norm(view) == 0 \
                or np.linalg.norm(np.cross(view, (0.0, 1.0, 0.0))) <= 1e-9 * np.linalg.norm(view):
            _refuse(path, f"camera({i})", got, "two different finite points whose view is "
                    "not vertical (up is +y: a vertical view has no roll)", "returned")
        return got

    def lights(i: int):
        got = _call(path, "lights", lights_fn, i)
        if not isinstance(got, dict):
            _refuse(path, f"lights({i})", got, "{shape key: (r, g, b)}", "returned")
        for key, rgb in got.items():
            if not isinstance(shapes.get(key), dict) or key in ("sensor", "integrator"):
                keys = [k for k, v in shapes.items()
                        if isinstance(v, dict) and k not in ("type", "sensor", "integrator")]
                _refuse(path, f"lights({i})'s key", key,
                        f"a shape key of build()'s dictionary: {', '.join(map(str, keys))}")
            try:
                value = np.asarray(rgb, np.float64).reshape(3)
            except (TypeError, ValueError):
                value = np.array([np.nan])
            if not np.isfinite(value).all() or (value < 0).any():
                _refuse(path, f"lights({i})[{key!r}]", rgb,
                        "(r, g, b), three finite numbers >= 0")
            lit[0] = lit[0] or bool((value > 0).any())
        return got

    lit = [emitters > 0]
    for i in range(frames):
        for name, fn in (("camera", camera), ("lights", lights)):
            # called again for each render of the frame: another answer (an unseeded random
            # number) gives its noisy images and reference different scenes
            check_same_build(fn(i), fn(i), f"--scene {path}", f"{name}({i})", "value",
                             "every render of the frame")
    if not lit[0]:
        raise DbenchInputError(f"--scene {path}: no frame has an emitter (build()'s dictionary "
                               f"holds none and lights(i) gives no radiance above 0), so every "
                               f"image is black and every method would score perfectly; add a "
                               f"light")
    return camera, lights


def sequence_fov(sensor: dict, path: str) -> float:
    """The field of view (degrees) a sequence file's frames are rendered with, read from
    build()'s sensor as a steady file's is (:func:`dbench.datasets.scenes.build.own_camera`):
    its ``fov``, else the fov along x Mitsuba makes of its ``focal_length`` (50 mm where it
    states neither; :func:`dbench.resolution.focal_fov`). A focal length used to be dropped
    for 39.3° (24 mm rendered at 39.3° instead of 71.6°). The frames are seen through a
    perspective camera at ``camera(i)``, so a sensor of another type (a thin lens's depth of
    field, an orthographic view) is refused rather than rendered as another camera."""
    kind = sensor.get("type", "perspective")
    if kind != "perspective":
        _refuse(path, "build()'s sensor type", kind, "\"perspective\": a sequence scene is "
                "seen through a perspective camera at camera(i), taking the sensor's fov or "
                "focal_length")
    if "fov" in sensor:
        return float(sensor["fov"])
    return focal_fov(sensor.get("focal_length", "50mm"), sensor.get("film"))


def _call(path: str, name: str, fn, i: int):
    try:
        return fn(i)
    except DbenchInputError:
        raise
    except Exception as exc:  # the file's own code: its failure is the file's, named as such
        raise DbenchInputError(f"--scene {path}: {name}({i}) failed: {type(exc).__name__}: "
                               f"{exc}") from None


def _number(path: str, name: str, value, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, Real) or not math.isfinite(value):
        _refuse(path, name, value, f"a finite number ({what})")
    return float(value)


def _count(path: str, name: str, value, default: int) -> int:
    if value is _MISSING:
        return default
    if isinstance(value, bool) or not isinstance(value, Integral) or not 1 <= value <= MAX_COUNT:
        _refuse(path, name, value, f"an integer in [1, {MAX_COUNT}]")
    return int(value)


def _refuse(path: str, name: str, value, valid: str, verb: str = "is") -> None:
    raise DbenchInputError(f"--scene {path}: {name} {verb} {value!r}; give {valid}")


__all__ = ["settings", "sequence_functions", "sequence_fov", "KINDS", "TRANSIENT_INTEGRATORS"]
