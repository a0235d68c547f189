"""Plugins: denoisers and scenes that live outside this repository.

Three ways in, all loaded the same way and idempotent (loading twice registers once):

* **Entry points** of installed distributions, found with no configuration::

      [project.entry-points."dbench.methods"]
      box3 = "dbench_example_plugin:Box3"          # a Denoiser subclass, or a module
      [project.entry-points."dbench.scenes"]
      my-room = "my_pkg.scenes:my_room"            # a Scene, a function returning one,
                                                   # or build(mi, res) -> dict
                                                   # (or build(mi, width, height))
* ``--plugin MODULE_OR_FILE.py`` on the command line (repeatable, before or after the
  subcommand);
* ``DBENCH_PLUGINS``: an ``os.pathsep``-separated list of modules or ``.py`` files.

A ``.py`` file is imported under a unique, deterministic module name
(``dbench_plugin_<stem>_<hash of its path>``), so the same file loads once per process and
worker processes give the same classes the same names.

Discovery is lazy: the registry calls :func:`ensure_loaded` on its first lookup (after the
built-in methods, which importing :mod:`dbench.registry` registers), so
``dbench.registry.available()`` includes plugins in any process, sweep workers included.
Callers import :mod:`dbench.registry` before loading a plugin, so the built-in names are
taken first (this module never imports the methods itself). A plugin that fails to import is recorded as *broken* with the reason:
``dbench list`` shows it, asking for it (``--method NAME``, ``--plugin FILE``) raises
:class:`PluginError` (exit 2 on the command line), and every other method keeps working.

    >>> from dbench import plugins
    >>> plugins.load("examples/dbench-example-plugin/dbench_example_plugin/__init__.py")  # doctest: +SKIP
    Plugin(spec=..., origin='--plugin', ok=True, provides=['box3'], ...)
"""
from __future__ import annotations

import hashlib
import importlib
import importlib.util
import inspect
import os
import sys
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable

from .denoiser import _REGISTRY, Denoiser, defined_in, register
from .errors import DbenchInputError

#: Entry-point groups.
METHOD_GROUP = "dbench.methods"
SCENE_GROUP = "dbench.scenes"
#: Environment variable: modules or .py files, separated by os.pathsep.
ENV_VAR = "DBENCH_PLUGINS"


class PluginError(DbenchInputError):
    """A plugin that was asked for could not be loaded (the message names it and says why)."""


@dataclass
class Plugin:
    """One plugin source and what loading it gave.

    Attributes:
        spec: ``group:NAME`` for an entry point, else the module name or absolute file path.
        origin: ``entry point (<distribution>)``, ``--plugin`` or ``DBENCH_PLUGINS``.
        target: what was imported (``module:Attr``, a module name or a file).
        ok: whether it loaded.
        error: the reason it did not (one line: ``ExceptionType: message``).
        provides: method and scene names it registered.
        name: the name a user asks for: the entry point's NAME, the file or module name.
    """

    spec: str
    origin: str
    target: str
    name: str
    ok: bool = False
    error: str = ""
    provides: list[str] = field(default_factory=list)


_LOCK = threading.RLock()
#: spec -> Plugin, in load order
_PLUGINS: dict[str, Plugin] = {}
#: explicitly requested specs (--plugin, DBENCH_PLUGINS, load()), in order: passed to workers
_REQUESTED: list[str] = []
_STATE = {"discovered": False, "loading": False}


def one_line(exc: BaseException) -> str:
    """``ExceptionType: message`` on one line (a plugin's failure, as ``dbench list`` and the
    refusals show it)."""
    return _one_line(exc)


def _one_line(exc: BaseException) -> str:
    if isinstance(exc, SystemExit):
        from .datasets.scenes.build import exit_message

        return (f"called {exit_message(exc)} while loading; a plugin module registers methods "
                f"or scenes when imported and must not end the process")
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


# ---------------------------------------------------------------------------------------------
# specs


def is_file_spec(spec: str) -> bool:
    return spec.endswith(".py") or os.sep in spec or (os.altsep or "\0") in spec


def normalise(spec: str) -> str:
    """A file spec as its absolute resolved path, a module name stripped."""
    spec = spec.strip()
    if is_file_spec(spec):
        return str(Path(spec).expanduser().resolve())
    return spec


def module_name_for_file(path: str | Path) -> str:
    """The module name a plugin file is imported under (the same in every process)."""
    p = Path(path).resolve()
    stem = "".join(c if c.isalnum() or c == "_" else "_" for c in p.stem)
    return f"dbench_plugin_{stem}_{hashlib.sha256(str(p).encode()).hexdigest()[:10]}"


def env_specs(environ: dict[str, str] | None = None) -> list[str]:
    """The entries of ``DBENCH_PLUGINS`` (empty ones dropped)."""
    value = (os.environ if environ is None else environ).get(ENV_VAR, "")
    return [s.strip() for s in value.split(os.pathsep) if s.strip()]


# ---------------------------------------------------------------------------------------------
# registration helpers


def _method_names() -> set[str]:
    return set(_REGISTRY)


def _scene_names() -> set[str]:
    mod = sys.modules.get("dbench.datasets.scenes.catalogue")
    return set(mod._CATALOGUE) if mod is not None else set()


def _register_method_object(name: str, obj: Any) -> None:
    if inspect.ismodule(obj):
        return  # its import registered what it has
    if not (inspect.isclass(obj) and issubclass(obj, Denoiser)):
        raise TypeError(f"{obj!r} is neither a Denoiser subclass nor a module")
    if any(c is obj for c in _REGISTRY.values()):
        if obj.name == name:
            return  # already registered (by @register, or an earlier load)
        # a class has one name: --method NAME of the entry point would be "unknown" while
        # `dbench list` shows the class under its own name, with nothing joining the two
        raise ValueError(f"entry point {name!r} names {obj.__module__}.{obj.__qualname__}, "
                         f"which is registered as {obj.name!r}: ask for --method {obj.name}, "
                         f"or give the entry point the name {obj.name!r}")
    if name in _REGISTRY:
        raise ValueError(f"method {name!r} is already registered by "
                         f"{_REGISTRY[name].__qualname__} ({defined_in(_REGISTRY[name])})")
    register(name)(obj)


def _register_scene_object(name: str, obj: Any) -> None:
    from .datasets.scenes.record import _CATALOGUE, Scene, register_scene

    if inspect.ismodule(obj):
        return
    if isinstance(obj, Scene):
        scene = obj
    elif callable(obj):
        params = [p for p in inspect.signature(obj).parameters.values()
                  if p.default is p.empty and p.kind in (p.POSITIONAL_ONLY,
                                                         p.POSITIONAL_OR_KEYWORD)]
        if len(params) >= 2:  # build(mi, res) or build(mi, width, height) -> dict
            from .datasets.scenes.build import plugin_build

            doc = (inspect.getdoc(obj) or "").strip().splitlines()
            scene = Scene(name=name, kind="steady", build=plugin_build(obj, name),
                          description=doc[0] if doc else f"plugin scene {name}")
        else:
            scene = obj()
            if not isinstance(scene, Scene):
                raise TypeError(f"{obj.__qualname__}() returned {type(scene).__name__}, "
                                "not a dbench.datasets.scenes.catalogue.Scene")
    else:
        raise TypeError(f"{obj!r} is not a Scene, a function returning one or build(mi, res)")
    if scene.name in _CATALOGUE and _CATALOGUE[scene.name] is not scene:
        existing = _CATALOGUE[scene.name]
        if getattr(existing, "build", None) is scene.build:
            return  # the same build function wrapped again: already there
        raise ValueError(f"scene {scene.name!r} is already registered")
    register_scene(scene)


# ---------------------------------------------------------------------------------------------
# loading


def _import_target(spec: str) -> Any:
    """Import a module name or a .py file (under its unique module name)."""
    if not is_file_spec(spec):
        return importlib.import_module(spec)
    path = Path(spec)
    if path.is_dir():  # it exists: "no such file" would send the user looking for a typo
        raise IsADirectoryError(f"{path} is a folder; give a .py file, or a module name "
                                f"(--plugin {path.name} with {path.parent} on PYTHONPATH)")
    if not path.is_file():
        raise FileNotFoundError(f"no such file {path}")
    name = module_name_for_file(path)
    if name in sys.modules:
        return sys.modules[name]
    mod_spec = importlib.util.spec_from_file_location(name, path)
    if mod_spec is None or mod_spec.loader is None:
        raise ImportError(f"cannot import {path}")
    module = importlib.util.module_from_spec(mod_spec)
    sys.modules[name] = module  # before exec: dataclasses, pickling and inspect need it
    try:
        mod_spec.loader.exec_module(module)
    except BaseException:
        sys.modules.pop(name, None)
        raise
    return module


def _record(plugin: Plugin, before: tuple[set[str], set[str]]) -> Plugin:
    methods_after, scenes_after = _method_names(), _scene_names()
    plugin.provides = sorted((methods_after - before[0]) | (scenes_after - before[1]))
    _PLUGINS[plugin.spec] = plugin
    return plugin


def load(spec: str, origin: str = "--plugin", strict: bool = True) -> Plugin:
    """Load a module or ``.py`` file once; returns its :class:`Plugin` record.

    With ``strict`` a failure raises :class:`PluginError` naming the plugin and the reason;
    otherwise it is recorded as broken. The caller has imported :mod:`dbench.registry` (and with
    it the built-in methods), so a plugin can never take a built-in name."""
    key = normalise(spec)
    with _LOCK:
        if key not in _REQUESTED:
            _REQUESTED.append(key)
        plugin = _PLUGINS.get(key)
        if plugin is None:
            name = Path(key).name if is_file_spec(key) else key
            plugin = Plugin(spec=key, origin=origin, target=key, name=name)
            before = (_method_names(), _scene_names())
            try:
                _import_target(key)
                plugin.ok = True
            # any failure makes the plugin broken; sys.exit too: a plugin never ends dbench
            # nor lends it its exit code
            except (Exception, SystemExit) as exc:  # noqa: BLE001
                plugin.error = _one_line(exc)
            _record(plugin, before)
    if strict and not plugin.ok:
        raise PluginError(f"plugin {spec} ({origin}) failed to load: {plugin.error}")
    return plugin


def load_all(specs: Iterable[str] = (), strict: bool = True) -> list[Plugin]:
    """Entry points, ``DBENCH_PLUGINS`` and ``specs`` (e.g. ``--plugin`` values), each once.

    With ``strict`` the first explicitly requested plugin that fails raises PluginError (after
    every one was tried); broken entry points never raise here (asking for one does)."""
    ensure_loaded()
    out = [load(s, origin="--plugin", strict=False) for s in specs]
    if strict:
        bad = [p for p in out if not p.ok]
        env_bad = [p for p in _PLUGINS.values() if p.origin == ENV_VAR and not p.ok]
        for p in bad + env_bad:  # a file by its path: two plugins may share a file name
            raise PluginError(f"plugin {p.target} ({p.origin}) failed to load: {p.error}")
    return out


def _load_entry_point(ep: Any, group: str) -> Plugin:
    dist = getattr(getattr(ep, "dist", None), "name", None) or "?"
    spec = f"{group}:{ep.name}"
    if spec in _PLUGINS:
        return _PLUGINS[spec]
    plugin = Plugin(spec=spec, origin=f"entry point ({dist})", target=ep.value, name=ep.name)
    before = (_method_names(), _scene_names())
    try:
        obj = ep.load()
        if group == METHOD_GROUP:
            _register_method_object(ep.name, obj)
        else:
            _register_scene_object(ep.name, obj)
        plugin.ok = True
    except (Exception, SystemExit) as exc:  # noqa: BLE001 - as in load()
        plugin.error = _one_line(exc)
        _scene_not_loaded(plugin, group)
    return _record(plugin, before)


def _scene_not_loaded(plugin: Plugin, group: str) -> None:
    """A broken scene entry point, noted in the scene catalogue (which cannot import this
    module): ``--scene NAME`` then names the failure, not an unknown scene."""
    if group == SCENE_GROUP:
        from .datasets.scenes.record import note_not_loaded

        note_not_loaded(plugin.name, _failure(plugin))


def discover_entry_points() -> list[Plugin]:
    """Load every ``dbench.methods`` and ``dbench.scenes`` entry point not loaded yet."""
    from importlib.metadata import distributions

    out = []
    with _LOCK:
        dists = list(distributions())
        for group in (METHOD_GROUP, SCENE_GROUP):
            # name -> {target: entry point}: one target seen twice is one distribution whose
            # folder is on sys.path twice; two targets are two claims on one name, which
            # importlib.metadata.entry_points(group=...) would give once, the other dropped
            by_name: dict[str, dict[str, Any]] = {}
            for ep in (ep for d in dists for ep in d.entry_points if ep.group == group):
                by_name.setdefault(ep.name, {}).setdefault(ep.value, ep)
            for name, eps in by_name.items():
                found = list(eps.values())
                out.append(_load_entry_point(found[0], group) if len(found) == 1
                           else _clash(name, found, group))
    return out


def _clash(name: str, eps: list[Any], group: str) -> Plugin:
    """The record of entry point ``name`` declared by two distributions for two targets: broken,
    none of them loaded, since which one sys.path would find first is no choice of the user's
    (asking for it names both)."""
    spec = f"{group}:{name}"
    if spec not in _PLUGINS:
        dists = [getattr(getattr(ep, "dist", None), "name", None) or "?" for ep in eps]
        _PLUGINS[spec] = Plugin(
            spec=spec, origin=f"entry points ({', '.join(dists)})",
            target=", ".join(ep.value for ep in eps), name=name,
            error=f"ValueError: entry point {name!r} is declared by "
                  + " and by ".join(f"{d} ({ep.value})" for d, ep in zip(dists, eps))
                  + "; uninstall one of them, or give one another name")
        _scene_not_loaded(_PLUGINS[spec], group)
    return _PLUGINS[spec]


def ensure_loaded() -> None:
    """Discover entry points and ``DBENCH_PLUGINS`` once per process (cheap afterwards).

    Called by the registry on lookup; safe to call from a plugin's own import (re-entrant)."""
    if _STATE["discovered"] or _STATE["loading"]:
        return
    with _LOCK:
        if _STATE["discovered"] or _STATE["loading"]:
            return
        _STATE["loading"] = True
        try:
            discover_entry_points()
            for s in env_specs():
                load(s, origin=ENV_VAR, strict=False)
            _STATE["discovered"] = True
        finally:
            _STATE["loading"] = False


def requested() -> list[str]:
    """Explicitly loaded specs (``--plugin``, ``DBENCH_PLUGINS``, :func:`load`), normalised,
    in order: what a worker process loads to see the same methods."""
    return list(_REQUESTED)


def worker_init(specs: Iterable[str]) -> None:
    """Start-up of a sweep worker (process pool initializer, Ray task): the same plugins as the
    parent. Failures are recorded, not raised (the parent already refused broken ones)."""
    ensure_loaded()
    for s in specs:
        load(s, strict=False)


def all_plugins() -> list[Plugin]:
    """Every plugin seen so far (loaded or broken), in load order."""
    ensure_loaded()
    return list(_PLUGINS.values())


def broken() -> list[Plugin]:
    return [p for p in all_plugins() if not p.ok]


def _failure(p: Plugin) -> str:
    """The sentence saying which plugin failed to load and why."""
    return f"plugin {p.name} ({p.origin}, {p.target}) failed to load: {p.error}"


def broken_reason(name: str) -> str:
    """``''`` unless ``name`` is a broken plugin: the sentence saying which and why."""
    for p in list(_PLUGINS.values()):
        if not p.ok and name in (p.name, p.spec):
            return _failure(p)
    return ""


def left_out(option: str, group: str = METHOD_GROUP) -> str:
    """``''``, or one line saying which plugins that may hold what ``option all`` takes failed
    to load and why, as ``dbench list`` shows them under "Broken plugins (not loaded)"
    (README.md "Add your own denoiser"): for methods (``group`` METHOD_GROUP) every broken
    plugin but a scene entry point; for scenes (SCENE_GROUP) the broken scene entry points,
    the scenes ``all`` never lists (a ``--plugin`` file or ``DBENCH_PLUGINS`` entry that failed
    has refused the command already, dbench.cli.main)."""
    scenes = group == SCENE_GROUP
    bad = [p for p in broken() if p.spec.startswith(f"{SCENE_GROUP}:") == scenes]
    what = "these scene plugins" if scenes else "what these plugins hold"
    if not bad:
        return ""
    return f"{option} all leaves out {what}: " + "; ".join(_failure(p) for p in bad)


def _reset_for_tests() -> None:
    """Forget every plugin record (not the registered classes): tests only."""
    with _LOCK:
        _PLUGINS.clear()
        _REQUESTED.clear()
        _STATE["discovered"] = False


__all__ = ["METHOD_GROUP", "SCENE_GROUP", "ENV_VAR", "Plugin", "PluginError", "load",
           "load_all", "discover_entry_points", "ensure_loaded", "requested", "worker_init",
           "all_plugins", "broken", "broken_reason", "left_out", "module_name_for_file",
           "env_specs"]
