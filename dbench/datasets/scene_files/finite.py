"""A scene file's numbers are finite, or the file is refused before anything renders
(README.md, "Mitsuba scene files").

Mitsuba loads ``nan`` and ``inf`` wherever a number goes (``<rgb value="1, nan, 1">``, a
``<default>``, a ``"value"`` of a Python file's dictionary) and renders the samples they reach
as NaN; dbench counts a non-finite sample as 0 (:mod:`dbench.datasets.render_moments`), so the
noisy images and the reference of such a scene were silently those of another scene (a light
without its green), where ``--scene-param L=nan`` was already refused for that reason
(:func:`dbench.datasets.scene_files.load.parse_scene_params`). :func:`check_state` refuses a
non-finite value of an XML file's parse (floats, points and vectors, colours, spectra,
transforms), :func:`check_dictionary` one of a Python file's ``build()`` dictionary, each in
one line naming where it is.
"""
from __future__ import annotations

import numpy as np

from ...errors import DbenchInputError
from ..mitsuba_env import mitsuba
from .xml import where


def check_state(state, path: str) -> None:
    """DbenchInputError naming the first property of the parse ``state`` holding a number
    that is not finite."""
    mi = mitsuba()
    kind = mi.Properties.Type
    for node in state.nodes:
        for key in node.props.keys():
            t = node.props.type(key)
            if t not in (kind.Float, kind.Vector, kind.Color, kind.Spectrum, kind.Transform):
                continue
            value = node.props.get(key)
            if t == kind.Spectrum:
                numbers, shown = list(value.values) + list(value.wavelengths), list(value.values)
            elif t == kind.Transform:
                numbers = shown = np.asarray(value.matrix, np.float64)
            else:
                numbers = shown = value
            if not np.isfinite(np.asarray(numbers, np.float64)).all():
                text = np.array2string(np.asarray(shown, np.float64).ravel(), separator=", ")
                raise DbenchInputError(
                    f"--scene {path}: {node.props.plugin_name()} {key} at "
                    f"{where(state, node)} is {text}; give finite numbers (Mitsuba renders "
                    f"NaN where a non-finite value reaches a sample)")


def check_dictionary(d, path: str, at: str = "build()'s dictionary") -> None:
    """DbenchInputError naming the first entry of the dictionary ``d`` (nested dictionaries,
    lists, NumPy arrays and Mitsuba's vector and transform types) that holds a number that is
    not finite. Loaded objects and strings are left alone."""
    if isinstance(d, dict):
        for key, value in d.items():
            check_dictionary(value, path, f"{at}[{key!r}]")
        return
    if isinstance(d, (str, bytes)) or d is None:
        return
    matrix = getattr(d, "matrix", None)  # mi.ScalarTransform4f
    try:
        numbers = np.asarray(d if matrix is None else matrix, np.float64)
    except (TypeError, ValueError):
        return  # not numbers: a loaded object, a name
    if not np.isfinite(numbers).all():
        raise DbenchInputError(f"--scene {path}: {at} is {d!r}; give finite numbers (Mitsuba "
                               f"renders NaN where a non-finite value reaches a sample)")


__all__ = ["check_state", "check_dictionary"]
