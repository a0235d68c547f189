"""The optional module attributes of a Python scene file, checked when the file is resolved
(README.md, "Python scene files"; :mod:`dbench.datasets.scene_files.load` lists them).

Each is a number of a stated kind, or the file is refused in one line naming the attribute,
the value and what it may be (exit 2), before anything renders: a value that is not a number
used to end in an internal error, and a fractional count (``frames = 2.7``, ``bins = 2.5``) was
cut to an integer without a word.
"""
from __future__ import annotations

import math
from numbers import Integral, Real
from typing import Any

from ...errors import DbenchInputError

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


def _number(path: str, name: str, value, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, Real) or not math.isfinite(value):
        _refuse(path, name, value, f"a finite number ({what})")
    return float(value)


def _count(path: str, name: str, value, default: int) -> int:
    if value is _MISSING:
        return default
    if isinstance(value, bool) or not isinstance(value, Integral) or value < 1:
        _refuse(path, name, value, "an integer >= 1")
    return int(value)


def _refuse(path: str, name: str, value, valid: str) -> None:
    raise DbenchInputError(f"--scene {path}: {name} is {value!r}; give {valid}")


__all__ = ["settings", "KINDS", "TRANSIENT_INTEGRATORS"]
