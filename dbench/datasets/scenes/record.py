"""What a scene is: the :class:`Scene` record every kind builds on (steady here; sequence and
transient scenes subclass it) and the catalogue dictionary that scene modules and plugins register
into. Nothing here renders; :mod:`dbench.datasets.scenes.catalogue` resolves names, files and folders."""
from __future__ import annotations

from copy import deepcopy
from dataclasses import dataclass, field
from typing import Any, Callable

from .build import call_build, check_film, dictionary_plan

STEADY_BUFFERS = frozenset({"color", "albedo", "normal", "depth", "position", "emitter",
                            "stats", "reference"})


@dataclass(frozen=True, eq=False)
class Scene:
    """A catalogue entry.

    Attributes:
        name: catalogue name, used on the command line and in cache keys.
        kind: ``steady`` (``sequence`` and ``transient`` come with their datasets).
        description: one line for ``dbench list`` and reports.
        build: ``build(mi, res) -> dict`` for ``mi.load_dict``, ``res`` a
            :class:`~dbench.resolution.Resolution` (an int equal to the width, with ``width``
            and ``height``, unpacking as (width, height)), or ``build(mi, width, height)``
            (:mod:`dbench.datasets.scenes.build`; README.md, "Python scene files"). The
            dictionary's film must have the requested size.
        max_depth: path length of the ``path`` integrator of a scene without an
            ``integrator_plan`` (part of the cache key through the dict).
        provides: buffers this scene can render.
        params: anything else that changes the pixels (goes into the cache key); for a scene
            made from ``--scene-param`` values, every declared parameter's value.
        ev: exposure (stops) of the tone map used by LDR metrics and PNGs.
        declared: the parameters ``--scene-param NAME=VALUE`` may set
            (:class:`dbench.datasets.scenes.params.Param`; empty: none).
        variant: ``variant(scene, values) -> Scene``, the scene of one set of values (every
            declared name, checked); :func:`dbench.datasets.scenes.params.bind` calls it.
        integrator_plan: the integrator that renders the colour where it is the dictionary's
            (:func:`dbench.datasets.scene_files.integrator.plan_dict`: Python scene files; a
            plugin's bare build function is planned when first rendered,
            :func:`dbench.datasets.scenes.build.dictionary_plan`); None: ``path`` with
            ``max_depth``.
        frame_meta: what every steady frame adds to its meta: how the render differs from
            the scene's file or dictionary (dbench.datasets.scene_files.fidelity).
    """

    name: str
    kind: str
    description: str
    build: Callable[[Any, int], dict]
    max_depth: int = 8
    provides: frozenset = STEADY_BUFFERS
    params: dict = field(default_factory=dict)
    ev: float = 0.0
    declared: tuple = ()
    variant: Callable[["Scene", dict], "Scene"] | None = None
    integrator_plan: Any = None
    frame_meta: dict = field(default_factory=dict)

    def scene_dict(self, mi, res) -> dict:
        d = call_build(self.build, mi, res, f"scene {self.name}")
        check_film(d, res, f"scene {self.name}", self.build)
        plan = dictionary_plan(self)
        d["integrator"] = (deepcopy(plan.render) if plan is not None
                           else {"type": "path", "max_depth": self.max_depth})
        return d

    #: whether the scene is rendered (False: read from files, dbench.datasets.folders.load)
    renders = True

    def objects_key(self) -> Any:
        """What :func:`dbench.datasets.mitsuba_env.focus` is told before this scene renders:
        the scene itself (a scene file's own loaded objects say their file instead)."""
        return self

    def key_dict(self, mi, res) -> dict:
        """What names this scene's content at ``res`` in cache keys: its dictionary (scene
        files whose dictionaries hold loaded objects describe themselves instead)."""
        return self.scene_dict(mi, res)


_CATALOGUE: dict[str, Scene] = {}


def register_scene(scene: Scene) -> Scene:
    """Add a Scene built elsewhere (e.g. the sequence scenes of datasets/sequence/load.py)."""
    if scene.name in _CATALOGUE and _CATALOGUE[scene.name] is not scene:
        raise ValueError(f"scene {scene.name!r} registered twice")
    _CATALOGUE[scene.name] = scene
    return scene


#: scene name -> why the plugin meant to register it did not load: a scene entry point that
#: failed (dbench.plugins, above this layer, notes it here), so that asking for the scene names
#: the failure rather than an unknown name
_NOT_LOADED: dict[str, str] = {}


def note_not_loaded(name: str, why: str) -> None:
    """Record that scene ``name`` was not loaded, and ``why`` (one sentence)."""
    _NOT_LOADED[name] = why


def not_loaded(name: str) -> str:
    """``''`` unless ``name`` is a scene whose plugin failed to load: the sentence saying why."""
    return "" if name in _CATALOGUE else _NOT_LOADED.get(name, "")


def available() -> list[str]:
    return sorted(_CATALOGUE)
