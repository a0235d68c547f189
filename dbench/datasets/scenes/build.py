"""Calling a scene's ``build``: the two signatures README.md documents ("Python scene files")
and what dbench checks around the call.

* ``build(mi, width, height) -> dict``: two ints;
* ``build(mi, res) -> dict``: one :class:`~dbench.resolution.Resolution`, an ``int`` equal to
  the width (a scene written when ``res`` was one side, ``"width": res, "height": res``, keeps
  working for square images) that also has ``res.width`` and ``res.height`` and unpacks as
  ``width, height = res``.

The form is read from the signature: three required positional parameters, or parameters 2 and
3 named ``width`` and ``height``, make the first; anything else the second (the catalogue's own
builds, ``build(mi, res, extra=...)`` included).

A ``build`` is code from outside dbench when it comes from a scene file or a plugin, so the call
never lets it end the process: ``sys.exit`` inside it becomes a DbenchInputError naming the
scene (exit 2), and a film whose size is not the requested one (``"height": res`` of a
non-square request) is refused with the line to write instead of rendering the wrong image. A
plugin's ``Scene`` renders its build's film as it is, so a film whose reconstruction filter is
not a box (hdrfilm's default is a Gaussian) is refused naming the scene, its file and the entry
to write (:func:`check_box_filter`): each 1-spp pass must keep every sample in its own pixel,
as the per-sample statistics need (README.md, "How renders work").

Nor may it change Mitsuba's variant (``mi.set_variant("scalar_rgb")``, as Mitsuba's
tutorials begin): the renders would be made in that variant while the cache keys, the cells
and the report name the one dbench chose (README.md, "How renders work"), so the variant is
put back and the scene refused (:func:`keeps_variant`).

A scene that has no emitter renders black images, which every method matches perfectly, so it
is refused before anything renders (:func:`check_lit`). A plugin's bare build function
(:func:`plugin_build`) renders its dictionary's integrator by the rules of Python scene files
(:func:`dictionary_plan`, dbench.datasets.scene_files.integrator.plan_dict), and its frames
state how the render differs from the dictionary as a scene file's do
(:func:`check_plugin_scene` fills ``Scene.frame_meta``).
"""
from __future__ import annotations

import inspect
import re
from contextlib import contextmanager
from functools import lru_cache
from typing import Any, Callable

from ...errors import DbenchInputError
from ...resolution import FOV_SENSORS, Resolution, focal_fov, parse_res
from .parts import film_dict


@lru_cache(maxsize=512)
def takes_width_height(fn: Callable) -> bool:
    """Whether ``fn`` is ``build(mi, width, height)`` (module docstring) rather than
    ``build(mi, res)``."""
    try:
        params = [p for p in inspect.signature(fn).parameters.values()
                  if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]
    except (TypeError, ValueError):  # a builtin without a signature: the historical form
        return False
    required = [p for p in params if p.default is p.empty]
    if len(required) >= 3:
        return True
    return [p.name for p in params[1:3]] == ["width", "height"]


def exit_message(exc: SystemExit) -> str:
    """``sys.exit(0)`` as the call that raised ``exc`` (for messages)."""
    code = exc.code
    return f"sys.exit({code!r})" if code is not None else "sys.exit()"


@contextmanager
def keeps_variant(mi: Any, what: str, code: str):
    """Run a scene's own ``code`` (its build, a scene file's module) and refuse it, with
    Mitsuba's variant put back, where it changed the variant (module docstring)."""
    variant = getattr(mi, "variant", None)  # a stand-in for Mitsuba has none to keep
    before = variant() if variant is not None else None
    try:
        yield
    finally:
        after = variant() if variant is not None else None
        if after != before:
            mi.set_variant(before)
            raise DbenchInputError(
                f"{what}: {code} set Mitsuba's variant to {after}, but dbench renders in "
                f"{before} and names it in every cache key and result; remove mi.set_variant "
                f"from the scene (DBENCH_VARIANT={after} renders in {after})")


def call_build(fn: Callable, mi: Any, res: Any, what: str) -> dict:
    """``fn(mi, width, height)`` or ``fn(mi, Resolution)`` (module docstring); ``what`` names
    the scene in the DbenchInputError raised when ``fn`` calls ``sys.exit`` or changes
    Mitsuba's variant."""
    size = Resolution.of(res)
    try:
        if takes_width_height(fn):
            with keeps_variant(mi, what, f"build(mi, {size.width}, {size.height})"):
                return fn(mi, size.width, size.height)
        with keeps_variant(mi, what, f"build(mi, res={size.key})"):
            return fn(mi, size)
    except SystemExit as exc:
        form = (f"build(mi, {size.width}, {size.height})" if takes_width_height(fn)
                else f"build(mi, res={size.key})")
        raise DbenchInputError(f"{what}: {form} called {exit_message(exc)}; build must return "
                               f"a mi.load_dict dictionary") from None


def check_film(d: Any, res: Any, what: str, build: Callable | None = None) -> None:
    """Refuse a dictionary whose sensor film states another size than ``res`` (the error says
    what to write: ``res`` is the width as an int, so ``"height": res`` is wrong for a
    non-square request, and names the file of ``build``, the function that made ``d``)."""
    size = parse_res(res)
    sensor = d.get("sensor") if isinstance(d, dict) else None
    film = sensor.get("film") if isinstance(sensor, dict) else None
    if not isinstance(film, dict) or "width" not in film or "height" not in film:
        return
    try:
        got = (int(film["width"]), int(film["height"]))
    except (TypeError, ValueError):
        return
    if got != (size.width, size.height):
        what += f" ({source_of(build)})" if build is not None else ""
        raise DbenchInputError(
            f"{what}: build returned a {got[0]}×{got[1]} film for a {size.text} render; state "
            f"the film as \"width\": res.width, \"height\": res.height (or width, height = res), "
            f"or define build(mi, width, height)")


def own_camera(d: dict, res) -> dict:
    """``d`` with dbench's film, sampler and field-of-view axis on its sensor (the ``fov`` it
    states is read along x, Mitsuba's default, and kept along the smaller side; a sensor that
    states a ``focal_length`` instead, or neither, gets the fov along x that Mitsuba makes of
    it for the dictionary's own film, :func:`focal_fov`): what scene files and plugins' build
    functions render with (dbench.datasets.scene_files.load). Other sensors (orthographic ...)
    take no field of view and keep theirs."""
    d = dict(d)
    sensor = dict(d["sensor"])
    if sensor.get("type", "perspective") in FOV_SENSORS:
        if "fov" not in sensor:
            sensor["fov"] = focal_fov(sensor.pop("focal_length", "50mm"), sensor.get("film"))
        sensor["fov_axis"] = parse_res(res).fov_axis
    sensor["film"] = film_dict(res)
    sensor["sampler"] = {"type": "independent"}
    d["sensor"] = sensor
    return d


def plugin_build(fn: Callable, name: str) -> Callable[[Any, Any], dict]:
    """The ``build`` of a plugin's scene given as a bare function (an entry point's
    ``build(mi, res)`` or ``build(mi, width, height)``): called in either form, and its sensor
    given dbench's film, sampler and field-of-view axis, as for Python scene files
    (dbench.datasets.scene_files.load), so it renders at any size. The same function gives the
    same adapter, so registering it twice registers once."""
    return _plugin_build(fn, name)


@lru_cache(maxsize=None)
def _plugin_build(fn: Callable, name: str) -> Callable[[Any, Any], dict]:
    def build(mi, res):
        d = call_build(fn, mi, res, f"scene {name}")
        if not isinstance(d, dict) or not isinstance(d.get("sensor"), dict):
            raise DbenchInputError(f"scene {name}: build must return a mi.load_dict dictionary "
                                   f"with a 'sensor' dictionary")
        return own_camera(d, res)

    build.__doc__ = fn.__doc__
    build.wrapped = fn
    return build


#: Mitsuba's message for a ``"type"`` it has no plugin of (mi.load_dict raises RuntimeError).
_UNKNOWN_PLUGIN = re.compile(r'node "([^"]*)".*?Plugin "([^"]+)" not found')


def probe_load(mi, d: dict, what: str, source: str = "the scene's dictionary"):
    """Load ``d`` (a build's dictionary) once at 8 px with dbench's camera, so a name Mitsuba
    does not know (an unknown plugin type, a misspelt property) is refused naming ``what``
    before anything renders, rather than failing inside a render as an internal error. The
    integrator is planned apart (dbench.datasets.scene_files.integrator), so it is left out.
    Returns the loaded scene."""
    probe = {k: v for k, v in own_camera(d, 8).items() if k != "integrator"}
    try:
        return mi.load_dict(probe)
    except Exception as exc:  # Mitsuba raises RuntimeError with its parser's message
        message = " ".join(str(exc).split())
        m = _UNKNOWN_PLUGIN.search(message)
        if m:
            raise DbenchInputError(
                f"{what}: Mitsuba ({mi.variant()}) has no plugin \"{m.group(2)}\" "
                f"(dictionary entry \"{m.group(1)}\"); use a Mitsuba plugin type such as "
                f"sphere, rectangle, diffuse, area") from None
        raise DbenchInputError(f"{what}: Mitsuba could not load {source}: {message}") from None


def source_of(fn: Callable) -> str:
    """The file ``fn`` is defined in, else its module's name (for messages)."""
    fn = getattr(fn, "wrapped", fn)
    try:
        return inspect.getsourcefile(fn) or fn.__module__
    except (TypeError, AttributeError):
        return str(getattr(fn, "__module__", None) or type(fn).__name__)


def check_box_filter(mi, d: dict, what: str) -> None:
    """Refuse a build dictionary whose film reconstructs with another filter than a box (one
    line naming ``what`` and the entry to write). The film is loaded by itself, so Mitsuba
    says which filter it has, also where the film names none (hdrfilm's default, a Gaussian)."""
    given = d["sensor"].get("film")
    film = {"type": "hdrfilm"} if given is None else given  # the sensor's default film
    if isinstance(film, dict):
        try:
            film = mi.load_dict(film)
        except Exception:  # noqa: BLE001 - the render names what Mitsuba cannot load
            return
    rfilter = film.rfilter() if hasattr(film, "rfilter") else None
    if rfilter is None or rfilter.is_box_filter():
        return
    stated = given.get("rfilter") if isinstance(given, dict) else None
    name = (stated.get("type") if isinstance(stated, dict) else None) or rfilter.class_name()
    raise DbenchInputError(
        f"{what}: the film's reconstruction filter is {name}"
        + (" (the film names none: hdrfilm's default)"
           if stated is None and not hasattr(given, "rfilter") else "")
        + "; dbench keeps each sample in its own pixel and needs a box filter: put "
        '"rfilter": {"type": "box"} in the film of the dictionary build returns')


def check_lit(loaded, what: str) -> None:
    """Refuse the loaded scene ``loaded`` when it has no emitter (area lights are their shapes'
    and count, as do environment maps and constant emitters), or when every emitter is an area
    light on a shape of zero surface area (a sphere of radius 0, a rectangle scaled to a line),
    which emits nothing: every image of it is black, and every method would score perfectly on
    it. Such a scene used to render its whole reference before the black image was refused,
    blaming the camera's view."""
    emitters = list(loaded.emitters())
    if not emitters:
        raise DbenchInputError(f"{what}: the scene has no emitter, so every image is black and "
                               f"every method would score perfectly; add a light")
    flat = [e.get_shape() for e in emitters if _zero_area(e.get_shape())]
    if len(flat) == len(emitters):
        names = ", ".join(dict.fromkeys(f"{s.class_name().lower()} {s.id()!r}".replace(" ''", "")
                                        for s in flat))
        raise DbenchInputError(f"{what}: every emitter is an area light on a shape of zero "
                               f"surface area ({names}), which emits nothing, so every image "
                               f"is black and every method would score perfectly; give a "
                               f"light's shape some area")


def _check_record(scene: Any) -> None:
    """A plugin's ``Scene(ev=..., max_depth=...)``, checked before anything renders: an ``ev``
    the tone map cannot use failed in the metrics after every method ran, and a max_depth of 0
    (no light gathered) rendered a black reference refused only afterwards."""
    from ...metrics.tonemapping import check_ev

    what = f"scene {scene.name} ({source_of(scene.build)})"
    try:
        check_ev(scene.ev)
    except DbenchInputError as exc:
        raise DbenchInputError(f"{what}: Scene {exc}") from None
    depth = scene.max_depth
    if scene.integrator_plan is None and (isinstance(depth, bool) or not isinstance(depth, int)
                                          or not (depth == -1 or depth >= 1)):
        raise DbenchInputError(f"{what}: Scene max_depth {depth!r}; give -1 (unlimited) or an "
                               f"integer of 1 or more (0 gathers no light)")


def check_same_build(first: Any, again: Any, what: str, call: str, returned: str = "dictionary",
                     renders: str = "every render") -> None:
    """Refuse a scene function whose two calls ``first`` and ``again`` (the same arguments)
    gave different answers (random numbers without a seed, the time): a build function's
    dictionary, or a sequence file's ``camera(i)`` / ``lights(i)`` (``returned="value"``,
    ``renders="every render of the frame"``). dbench calls it for each render, so the noisy
    images, the features and the reference would show different scenes, each cached under its
    own key, and be scored against one another without a word."""
    from ..cache import canonical

    where = _first_difference(canonical(first), canonical(again))
    if where is not None:
        raise DbenchInputError(f"{what}: {call} returned another {returned} when called again "
                               f"(at {where}); dbench calls it for {renders}, so every call "
                               f"must describe the same scene: seed its random numbers or draw "
                               f"them once, at module level")


def _first_difference(a: Any, b: Any, at: str = "the top") -> str | None:
    """Where two :func:`~dbench.datasets.cache.canonical` descriptions first differ."""
    if isinstance(a, dict) and isinstance(b, dict) and a.keys() == b.keys():
        for k in a:
            found = _first_difference(a[k], b[k], k if at == "the top" else f"{at}.{k}")
            if found:
                return found
        return None
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        return next((f for i, (x, y) in enumerate(zip(a, b))
                     if (f := _first_difference(x, y, f"{at}[{i}]"))), None)
    return None if a == b else repr(at) if at != "the top" else at


def _zero_area(shape) -> bool:
    """Whether ``shape`` (an area light's, None for other emitters) has no surface."""
    if shape is None:
        return False
    try:
        import drjit as dr
        return float(dr.max(dr.ravel(shape.surface_area()))[0]) <= 0.0
    except Exception:  # a shape that does not compute its area: assume it emits
        return False


def dictionary_plan(scene: Any):
    """The integrator plan ``scene`` renders its colour with: its own ``integrator_plan`` (a
    Python scene file's), the plan of its dictionary for a plugin's bare build function
    (:func:`plugin_build`; planned once per variant), else None (the catalogue's path)."""
    if scene.integrator_plan is not None or getattr(scene.build, "wrapped", None) is None:
        return scene.integrator_plan
    from ..mitsuba_env import mitsuba

    return _adapter_record(scene, mitsuba().variant())[0]


@lru_cache(maxsize=None)
def _adapter_record(scene: Any, variant: str) -> tuple:
    """(plan, fidelity record) of a plugin build function's dictionary, built at 8 px as it
    returns it (its own film and sampler, before :func:`own_camera`)."""
    from ..mitsuba_env import mitsuba
    from ..scene_files.fidelity import dict_record
    from ..scene_files.integrator import plan_dict

    d = call_build(scene.build.wrapped, mitsuba(), 8, f"scene {scene.name}")
    if not isinstance(d, dict) or not isinstance(d.get("sensor"), dict):
        raise DbenchInputError(f"scene {scene.name}: build must return a mi.load_dict dictionary "
                               f"with a 'sensor' dictionary")
    plan = plan_dict(d.get("integrator"), scene.name, source="the build function's dictionary")
    return plan, dict_record(plan, d)


_PROBED: set = set()


def check_plugin_scene(scene: Any) -> None:
    """:func:`probe_load` of a steady scene whose ``build`` comes from outside dbench (a
    plugin's or an entry point's), once per scene and variant in a process; dbench's own
    catalogue is trusted and costs nothing here."""
    from ..mitsuba_env import mitsuba

    fn = getattr(scene.build, "wrapped", scene.build)
    if str(getattr(fn, "__module__", "")).startswith("dbench."):
        return
    _check_record(scene)
    mi = mitsuba()
    key = (id(scene), mi.variant())
    if key in _PROBED:
        return
    d = call_build(scene.build, mi, 8, f"scene {scene.name}")
    if not isinstance(d, dict) or not isinstance(d.get("sensor"), dict):
        raise DbenchInputError(f"scene {scene.name}: build must return a mi.load_dict "
                               f"dictionary with a 'sensor' dictionary")
    check_same_build(d, call_build(scene.build, mi, 8, f"scene {scene.name}"),
                     f"scene {scene.name} ({source_of(scene.build)})", "build")
    check_lit(probe_load(mi, d, f"scene {scene.name}"), f"scene {scene.name}")
    check_box_filter(mi, d, f"scene {scene.name} ({source_of(scene.build)})")
    if dictionary_plan(scene) is not None:  # a plugin's bare build function
        from ..scene_files.fidelity import report_lines

        rec = _adapter_record(scene, mi.variant())[1]
        scene.frame_meta.update(scene_file=rec, scene_file_settings=report_lines(rec))
    else:
        check_own_integrator(scene, d.get("integrator"))
    _PROBED.add(key)


def integrator_settings(integrator: Any) -> tuple[str, list[str]]:
    """(type, its settings other than ``max_depth``, sorted) of a build dictionary's
    ``"integrator"``: what decides whether dbench's own ``path`` (or ``volpath``) at that depth
    renders it as it is (a loaded object: its class name, settings unknown)."""
    if not isinstance(integrator, dict):
        return type(integrator).__name__, []
    return str(integrator.get("type")), sorted(set(integrator) - {"type", "max_depth"})


def check_own_integrator(scene: Any, integrator: Any) -> None:
    """A plugin's ``Scene`` renders with ``path`` at its own ``max_depth`` (README.md, "Python
    scene files": it sets the depth): a dictionary integrator of another type or with other
    settings is refused, which would otherwise be replaced without a word; another
    ``max_depth`` is stated in the frames' settings (``Scene.frame_meta``)."""
    if integrator is None:
        return
    name, extra = integrator_settings(integrator)
    if name != "path" or extra:
        given = f"{name}" + (f" with {', '.join(extra)}" if extra else "")
        raise DbenchInputError(
            f"scene {scene.name} ({source_of(scene.build)}): its dictionary's integrator is "
            f"{given}, but a Scene renders with path at its max_depth ({scene.max_depth}); "
            f"remove it, or register the build function itself (an entry point), which "
            f"renders its dictionary's integrator")
    depth = integrator.get("max_depth")
    if depth is not None and depth != scene.max_depth:
        scene.frame_meta.setdefault("scene_file_settings", {})["max_depth"] = (
            f"{scene.max_depth} (file: {depth}) — the Scene's max_depth renders")


__all__ = ["call_build", "check_box_filter", "check_film", "check_lit", "check_same_build",
           "check_own_integrator", "check_plugin_scene", "dictionary_plan", "exit_message",
           "integrator_settings", "own_camera", "plugin_build", "probe_load", "source_of",
           "takes_width_height"]
