"""The integrator a Mitsuba XML scene file renders with in dbench: the file's own, wherever it
can be (README.md, "Mitsuba scene files").

The file's ``<integrator>`` is read from Mitsuba's parse of it (:mod:`dbench.datasets.scene_files.xml`),
so a setting made in an ``<include>``d fragment, through a ``<default>`` or a ``$name``
parameter counts exactly as Mitsuba counts it. dbench needs two things from the integrator that
renders the colour: one sample per pixel in each 1-spp pass (the passes are the individual
samples its statistics are made of) and an image that is the colour alone. Its G-buffers
(albedo, normal, depth, position) and emitter buffer come from passes of its own, whatever the
file's integrator is. Hence:

- an integrator that instantiates as a sampling integrator writing only the colour (``path``,
  ``direct``, ``volpath``, ``volpathmis``, ``prb``, ``prbvolpath``, ``depth``, …) is kept with
  every setting the file gives it (``max_depth = -1``, Mitsuba's "unlimited", passes through as
  -1);
- a wrapper is unwrapped to the integrator it holds, and the record says so: ``moment`` (dbench
  computes the per-sample statistics itself), ``aov`` (dbench makes its own AOVs) and
  ``stokes`` (polarization needs a polarized variant; dbench renders in RGB, so the image is the
  nested integrator's unpolarized intensity). A ``moment`` holding several integrators renders
  the first;
- anything else is replaced by ``path`` carrying the file's ``max_depth``, ``rr_depth`` and
  ``hide_emitters``, with the reason: a light-tracing integrator (``ptracer``) splats paths
  anywhere on the film, so a pass does not give each pixel one sample; an ``aov`` holding no
  integrator has no colour;
- a file without an integrator (Mitsuba renders nothing without one) renders with ``path`` and
  max_depth 8, as the catalogue does, and the record says so.

Two integrators at the top of one scene are refused as Mitsuba refuses them.

A Python scene file's dictionary (and a plugin's build function's) follows the same rules
(:func:`plan_dict`, README.md "Python scene files"): its ``"integrator"`` entry is kept,
unwrapped or replaced as above, and a dictionary without one renders with ``path``; a Python
file's module attribute ``max_depth``, where set, overrides the depth, and the notes say so.
"""
from __future__ import annotations

import re
from copy import deepcopy
from dataclasses import dataclass, replace

from ...errors import DbenchInputError
from ..mitsuba_env import mitsuba
from .xml import children, where

#: max_depth of the ``path`` integrator dbench renders a file without an integrator with.
DEFAULT_MAX_DEPTH = 8
#: what unwrapping each wrapper means for the image (module docstring)
WRAPPERS = {
    "moment": "moment unwrapped: dbench renders its nested integrator's colour and computes "
              "the per-sample statistics itself (Mitsuba's moment image holds XYZ colour and "
              "second moments)",
    "aov": "aov unwrapped: dbench renders its nested integrator's colour and makes its own "
           "AOV pass (albedo, normal, depth, position)",
    "stokes": "stokes unwrapped: polarization needs a polarized variant and dbench renders in "
              "RGB, so the image is the nested integrator's intensity without polarization",
}
#: settings a replacement ``path`` takes over from the file's integrator
CARRIED = ("max_depth", "rr_depth", "hide_emitters")
#: Mitsuba stores max_depth = -1 as the largest unsigned 32-bit value and prints it so
_UNLIMITED = 2 ** 32 - 1


@dataclass(frozen=True)
class IntegratorPlan:
    """What renders the colour of a scene file.

    Attributes:
        render: the ``mi.load_dict`` dictionary of the integrator dbench renders with.
        integrator: its plugin name.
        file_integrator: the file's, wrappers included (``"moment(path)"``); None when the file
            names none.
        max_depth, rr_depth: the values the rendering integrator uses (Mitsuba's defaults where
            the file sets none; -1: unlimited); None where it has no such setting (``direct``).
        hide_emitters: the file's setting, None where it sets none.
        replaced: why dbench renders another integrator than the file's, else None.
        notes: the other ways the rendering integrator differs from the file's (unwrapped
            wrappers, a default where the file names no integrator).
    """

    render: dict
    integrator: str
    file_integrator: str | None
    max_depth: int | None
    rr_depth: int | None
    hide_emitters: bool | None
    replaced: str | None = None
    notes: tuple[str, ...] = ()


def plan(state, path: str) -> IntegratorPlan:
    """The :class:`IntegratorPlan` of the file whose parser state is ``state`` (module
    docstring). DbenchInputError when the file has two integrators or Mitsuba refuses the
    file's integrator (its message)."""
    mi = mitsuba()
    found = children(state, state.root, mi.ObjectType.Integrator)
    if len(found) > 1:
        raise DbenchInputError(f"--scene {path}: {len(found)} <integrator>s "
                               f"(at {'; '.join(where(state, n) for _, n in found)}); Mitsuba "
                               f"renders a scene with one integrator")
    if not found:
        return _finish(path, {"type": "path", "max_depth": DEFAULT_MAX_DEPTH}, None, None,
                       (f"the file names no integrator (Mitsuba renders none without one); "
                        f"dbench renders path with max_depth {DEFAULT_MAX_DEPTH}",), {})
    node = found[0][1]
    chain: list[str] = []
    notes: list[str] = []
    while node.props.plugin_name() in WRAPPERS:
        name = node.props.plugin_name()
        nested = children(state, node, mi.ObjectType.Integrator)
        chain.append(name)
        if not nested:
            settings = _settings(state, node, path)
            replaced = (f"{name} holds no integrator, so its image has no colour; dbench "
                        f"renders the colour with path (max_depth {DEFAULT_MAX_DEPTH}) and "
                        f"makes its own AOVs")
            return _finish(path, {"type": "path", "max_depth": DEFAULT_MAX_DEPTH},
                           _chain(chain, None), replaced, tuple(notes), settings)
        if len(nested) > 1:
            notes.append(f"{name} holds {len(nested)} integrators; the first "
                         f"({nested[0][1].props.plugin_name()}) renders the image")
        notes.append(WRAPPERS[name])
        node = nested[0][1]
    return _keep_or_replace(mi, _settings(state, node, path), chain, notes, path)


def plan_dict(integrator, path: str, max_depth: int | None = None,
              source: str = "build()'s dictionary") -> IntegratorPlan:
    """The :class:`IntegratorPlan` of a ``mi.load_dict`` dictionary's ``"integrator"`` entry
    (None where it has none), by the rules :func:`plan` applies to a file (module docstring):
    Python scene files and plugins' build functions. Nested integrators of a wrapper are its
    entries that are dictionaries, in the dictionary's order. ``max_depth`` (a Python scene
    file's module attribute), when given, overrides the depth of the integrator that renders,
    and the notes say so. DbenchInputError when the entry is not a dictionary or Mitsuba
    refuses it."""
    mi = mitsuba()
    if integrator is None:
        depth = DEFAULT_MAX_DEPTH if max_depth is None else int(max_depth)
        return _finish(path, {"type": "path", "max_depth": depth}, None, None,
                       (f"{source} names no integrator (mi.load_dict gives a scene without "
                        f"one); dbench renders path with max_depth {depth}"
                        + (" (the module's max_depth)" if max_depth is not None else ""),), {})
    if not isinstance(integrator, dict) or not isinstance(integrator.get("type"), str):
        raise DbenchInputError(f"--scene {path}: {source} gives its integrator as "
                               f"{type(integrator).__name__}; give it as a dictionary such as "
                               f"{{\"type\": \"path\", \"max_depth\": 8}}, so dbench can read "
                               f"its settings")
    settings = deepcopy(integrator)
    chain: list[str] = []
    notes: list[str] = []
    while settings["type"] in WRAPPERS:
        name = settings["type"]
        nested = [v for v in settings.values() if isinstance(v, dict) and "type" in v]
        chain.append(name)
        if not nested:
            return _override(_empty_wrapper(name, chain, notes, settings, path), max_depth, path)
        if len(nested) > 1:
            notes.append(f"{name} holds {len(nested)} integrators; the first "
                         f"({nested[0]['type']}) renders the image")
        notes.append(WRAPPERS[name])
        settings = nested[0]
    return _override(_keep_or_replace(mi, settings, chain, notes, path), max_depth, path)


def _empty_wrapper(name: str, chain: list, notes: list, settings: dict,
                   path: str) -> IntegratorPlan:
    """A wrapper holding no integrator: its image has no colour, path renders it."""
    replaced = (f"{name} holds no integrator, so its image has no colour; dbench renders the "
                f"colour with path (max_depth {DEFAULT_MAX_DEPTH}) and makes its own AOVs")
    return _finish(path, {"type": "path", "max_depth": DEFAULT_MAX_DEPTH},
                   _chain(chain, None), replaced, tuple(notes), settings)


def _keep_or_replace(mi, settings: dict, chain: list, notes: list, path: str) -> IntegratorPlan:
    """The plan of the integrator ``settings`` the wrappers ``chain`` hold: kept where it can
    render dbench's passes, else path carrying its :data:`CARRIED` settings."""
    name = settings["type"]
    why = _cannot_keep(mi, _instantiate(settings, path), name)
    render = settings
    if why:
        render = {"type": "path", **{k: settings[k] for k in CARRIED if k in settings}}
    return _finish(path, render, _chain(chain, name), why, tuple(notes), settings)


def _override(p: IntegratorPlan, max_depth: int | None, path: str) -> IntegratorPlan:
    """``p`` with the module attribute ``max_depth`` in place of the depth it renders with,
    said in its notes."""
    if max_depth is None or p.max_depth == int(max_depth):
        return p
    if p.max_depth is None:
        note = (f"the module's max_depth {int(max_depth)} does not apply: {p.integrator} has "
                f"no max_depth")
        return replace(p, notes=p.notes + (note,))
    note = (f"max_depth {int(max_depth)} is the module's max_depth, which overrides the "
            f"integrator's {'unlimited' if p.max_depth == -1 else p.max_depth}")
    render = {**p.render, "max_depth": int(max_depth)}
    done = _finish(path, render, p.file_integrator, p.replaced, p.notes + (note,), {})
    return replace(done, hide_emitters=p.hide_emitters)


def _chain(wrappers: list[str], inner: str | None) -> str:
    """``moment(path)`` for the wrappers and the integrator they hold."""
    text = inner or ""
    for name in reversed(wrappers):
        text = f"{name}({text})" if text else name
    return text


def _settings(state, node, path: str) -> dict:
    """The ``mi.load_dict`` dictionary of an integrator node: its values as Mitsuba parsed
    them, nested integrators as dictionaries."""
    mi = mitsuba()
    d = {"type": node.props.plugin_name()}
    for key in node.props.keys():
        if node.props.type(key) != mi.Properties.Type.ResolvedReference:
            d[key] = node.props.get(key)
    for key, child in children(state, node):
        if child.type != mi.ObjectType.Integrator:
            raise DbenchInputError(f"--scene {path}: integrator {d['type']} holds a "
                                   f"{child.type.name} at {where(state, child)}; dbench reads "
                                   f"integrators whose settings are values and integrators")
        d[key] = _settings(state, child, path)
    return d


def _instantiate(d: dict, path: str):
    try:
        return mitsuba().load_dict(d)
    except Exception as exc:  # Mitsuba's own refusal of the settings
        raise DbenchInputError(f"--scene {path}: Mitsuba could not load it: integrator "
                               f"{d['type']}: {' '.join(str(exc).split())}") from None


def _cannot_keep(mi, integrator, name: str) -> str | None:
    """Why ``integrator`` cannot render dbench's 1-spp passes (None: it can)."""
    if isinstance(integrator, mi.AdjointIntegrator):
        return (f"{name} traces paths from the lights and splats them anywhere on the film, so "
                f"a 1-spp pass does not give each pixel one sample as dbench's per-sample "
                f"statistics need; path renders the same light transport")
    if not isinstance(integrator, mi.SamplingIntegrator):
        return (f"{name} is not a sampling integrator (one sample per pixel and pass), which "
                f"dbench's per-sample statistics need")
    extra = list(integrator.aov_names())
    if extra:
        return (f"{name} writes channels besides the colour ({', '.join(extra)}); dbench makes "
                f"its own AOVs")
    return None


def _finish(path: str, render: dict, file_integrator: str | None, replaced: str | None,
            notes: tuple, settings: dict) -> IntegratorPlan:
    """The plan, with the depths read back from the integrator Mitsuba builds of ``render``."""
    text = str(_instantiate(render, path))
    hide = settings.get("hide_emitters")
    depth = _depth(text, "max_depth")
    if depth == 0:
        # refused before the reference renders, where check_reference_lit would refuse the
        # black reference afterwards, blaming the lights
        raise DbenchInputError(f"--scene {path}: max_depth 0 ({render['type']}) gathers no "
                               f"light, not even a light seen directly, so every image is "
                               f"black and every method would score perfectly; give max_depth "
                               f"-1 (unlimited) or 1 or more")
    return IntegratorPlan(render=render, integrator=render["type"],
                          file_integrator=file_integrator,
                          max_depth=depth, rr_depth=_depth(text, "rr_depth"),
                          hide_emitters=None if hide is None else bool(hide),
                          replaced=replaced, notes=notes)


def _depth(text: str, key: str) -> int | None:
    """``key`` as the integrator prints it (-1 for unlimited), None where it has none."""
    m = re.search(rf"\b{key}\s*=\s*(-?\d+)", text)
    if not m:
        return None
    value = int(m.group(1))
    return -1 if value in (-1, _UNLIMITED) else value


__all__ = ["IntegratorPlan", "plan", "plan_dict", "DEFAULT_MAX_DEPTH", "WRAPPERS"]
