"""Mitsuba's own reading of a scene file: its parser's graph of the file, and the file's objects.

dbench reads what a Mitsuba XML file says through Mitsuba's parser (``mi.parser``), the code
``mi.load_file`` runs, so the values it reports and renders with are the ones Mitsuba sees:
``<include>`` fragments merged in place, ``<default>`` values and ``--scene-param`` values
substituted for ``$name``, ``<ref id>`` references resolved, files written for older Mitsuba
versions upgraded (README.md, "Mitsuba scene files").

:func:`parse` gives that graph without creating any object; :func:`load` creates the scene's
objects as ``mi.load_file`` does, except the file's integrators: dbench renders with the
integrator :mod:`dbench.datasets.scene_files.integrator` builds, so the file's own are created as
plain ``path`` integrators (an integrator that only exists in other variants, such as
``stokes`` in RGB, would otherwise stop the load). :func:`shape_groups` finds the
``shapegroup`` objects a scene keeps aside for its instances.
"""
from __future__ import annotations

from contextlib import contextmanager
from pathlib import Path

from ...errors import DbenchInputError
from ..mitsuba_env import mitsuba


def _config(mi):
    return mi.parser.ParserConfig(mi.variant())


def _message(exc: Exception) -> str:
    return " ".join(str(exc).split())


@contextmanager
def _resolver(mi, path: str):
    """The process's file resolver with the file's folder put first, for the time of one read,
    as ``mi.load_file`` sets it: ``<path>`` elements add to it, and the objects created after
    the parse look their files up in it. The process's own resolver is put back afterwards."""
    backup = mi.file_resolver()
    own = mi.FileResolver(backup)
    own.prepend(str(Path(path).parent))
    mi.set_file_resolver(own)
    try:
        yield
    finally:
        mi.set_file_resolver(backup)


def parse(path: str, params: dict[str, str]):
    """Mitsuba's parser state of the file at ``path`` with ``params`` (``$name`` values),
    references resolved and old versions upgraded; nothing is created. DbenchInputError with
    Mitsuba's message when the file does not parse."""
    mi = mitsuba()
    config = _config(mi)
    try:
        with _resolver(mi, path):
            state = mi.parser.parse_file(config, str(path), **dict(params))
            mi.parser.transform_upgrade(config, state)
            mi.parser.transform_resolve(config, state)
    except Exception as exc:  # Mitsuba raises RuntimeError with its parser's message
        raise DbenchInputError(f"--scene {path}: Mitsuba could not load it: "
                               f"{_message(exc)}") from None
    return state


def load(path: str, params: dict[str, str]):
    """The scene object of the file, built as ``mi.load_file(path, **params)`` builds it but
    with every integrator of the file created as a plain ``path`` (module docstring).
    DbenchInputError with Mitsuba's message when it does not load."""
    mi = mitsuba()
    config = _config(mi)
    try:
        with _resolver(mi, path):
            state = mi.parser.parse_file(config, str(path), **dict(params))
            mi.parser.transform_all(config, state)
            for node in state.nodes:
                if node.type == mi.ObjectType.Integrator:
                    for key in list(node.props.keys()):
                        del node.props[key]
                    node.props.set_plugin_name("path")
            return mi.parser.instantiate(config, state)
    except Exception as exc:
        raise DbenchInputError(f"--scene {path}: Mitsuba could not load it: "
                               f"{_message(exc)}") from None


def children(state, node, kind=None) -> list:
    """(property name, node) of the objects ``node`` holds, in the file's order; only those of
    ``kind`` (an ``mi.ObjectType``) when given."""
    mi = mitsuba()
    out = []
    for key in node.props.keys():
        if node.props.type(key) == mi.Properties.Type.ResolvedReference:
            child = state.nodes[node.props.get(key).index()]
            if kind is None or child.type == kind:
                out.append((key, child))
    return out


def where(state, node) -> str:
    """The file and line of ``node``, for messages."""
    return mitsuba().parser.file_location(state, node)


def shape_groups(loaded) -> list:
    """The ``shapegroup`` objects of the loaded scene. Mitsuba keeps them among the scene's
    children but not among ``scene.shapes()``, and a scene built from the shapes alone cannot
    create its ``instance`` shapes (Mitsuba fails with "Couldn't find key")."""
    mi = mitsuba()

    class _Children(mi.TraversalCallback):
        def __init__(self):
            mi.TraversalCallback.__init__(self)
            self.objects = []

        def put(self, name, value, flags, cpptype=None):
            if isinstance(value, mi.Object):
                self.objects.append(value)

        def put_value(self, name, ptr, flags, cpptype=None):
            pass

        def put_object(self, name, obj, flags):
            self.objects.append(obj)

    found = _Children()
    loaded.traverse(found)
    return [o for o in found.objects
            if isinstance(o, mi.Shape) and o.class_name().startswith("ShapeGroup")]


__all__ = ["parse", "load", "children", "where", "shape_groups"]
