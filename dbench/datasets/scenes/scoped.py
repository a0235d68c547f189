"""Which scene a ``--scene-param`` value is for: ``NAME=VALUE`` sets it for every scene of the
command, ``SCENE:NAME=VALUE`` for that one scene only (README.md, "Usage").

``SCENE`` is the scene as written in the command's scene option (``sweep --scenes``, ``run``
/ ``render`` / ``export --scene``): a catalogue name or a scene file path. A path may hold a
``:`` (``C:\\scenes\\room.xml``) and a value may too, so no character can split the scope off
by itself. The scope is therefore read against the scenes the command names: an item is
scoped to ``SCENE`` when it begins with ``SCENE:`` followed by ``NAME=`` (``NAME`` a letter or
``_`` then letters, digits or ``_``, as every parameter name), and it is unscoped when it
begins with ``NAME=``. An item that reads both ways (a scene named ``x=1.xml`` and the item
``x=1.xml:r=2``, or the scenes ``a`` and ``a:b=c.xml``) is refused in one line naming both
readings, never guessed; an item naming no scene of the command is refused naming the valid
ones. Both refusals come before anything renders (the command line exits 2).

A scene's own values (:func:`values_for`) are the unscoped ones and its scoped ones; one name
given both ways with two values for one scene is refused, as one name given twice is
(dbench.datasets.scene_files.load.parse_scene_params).

Example:
    >>> every, own = split(["spp=4", "my.xml:light=5"], ["cornell", "my.xml"], "--scenes")
    >>> every, own
    ({'spp': '4'}, {'my.xml': {'light': '5'}})
    >>> values_for(every, own, "my.xml")
    {'spp': '4', 'light': '5'}
"""
from __future__ import annotations

import re
from typing import Mapping, Sequence

from ...errors import DbenchInputError

_NAME_EQ = re.compile(r"\s*[A-Za-z_][A-Za-z0-9_]*\s*=")
#: ``:NAME=`` where a scope could end: to name the scope of an item naming no scene
_SCOPE_END = re.compile(r":\s*[A-Za-z_][A-Za-z0-9_]*\s*=")


def _parse(items: Sequence[str]) -> dict[str, str]:
    from ..scene_files.load import parse_scene_params

    return parse_scene_params(items)


def readings(item: str, scenes: Sequence[str]) -> list[tuple[str | None, str]]:
    """Every way to read ``item``: (None, ``NAME=VALUE``) for every scene, (scene,
    ``NAME=VALUE``) for one of ``scenes`` (as written)."""
    out: list[tuple[str | None, str]] = []
    if _NAME_EQ.match(item):
        out.append((None, item))
    for scene in dict.fromkeys(scenes):
        rest = item[len(scene) + 1:]
        if item.startswith(f"{scene}:") and _NAME_EQ.match(rest):
            out.append((scene, rest))
    return out


def _said(reading: tuple[str | None, str]) -> str:
    scene, rest = reading
    return f"{rest!r} for {'every scene' if scene is None else scene}"


def not_a_scene(item: str, scope: str, scenes: Sequence[str], option: str) -> DbenchInputError:
    """The refusal of ``item`` whose scope ``scope`` is none of ``scenes`` (given as
    ``option``)."""
    return DbenchInputError(
        f"--scene-param {item}: {scope!r} is not a scene of {option} "
        f"({', '.join(scenes) or 'none'}); SCENE:NAME=VALUE names SCENE as written there")


def split(items: Sequence[str] | None, scenes: Sequence[str], option: str
          ) -> tuple[dict[str, str], dict[str, dict[str, str]]]:
    """``--scene-param`` ``items`` of a command whose scenes are ``scenes`` (as written in
    ``option``) → ({name: value} for every scene, {scene: {name: value}} of the scoped ones);
    DbenchInputError, one line, for an item that reads two ways, names no scene of the
    command, is no ``[SCENE:]NAME=VALUE`` or gives one name two values (module docstring)."""
    every: list[str] = []
    scoped: dict[str, list[str]] = {}
    for item in map(str, items or []):
        found = readings(item, scenes)
        if len(found) > 1:
            raise DbenchInputError(
                f"--scene-param {item}: reads two ways, {_said(found[0])} or "
                f"{_said(found[1])}; write that scene another way in {option} and in the "
                f"scope (./NAME for a file)")
        if not found:
            end = _SCOPE_END.search(item)
            if end is None:
                raise DbenchInputError(f"--scene-param: expected NAME=VALUE or "
                                       f"SCENE:NAME=VALUE, got {item!r}")
            raise not_a_scene(item, item[:end.start()], scenes, option)
        scene, rest = found[0]
        (every if scene is None else scoped.setdefault(scene, [])).append(rest)
    shared = _parse(every)
    own = {}
    for scene, given in scoped.items():
        try:
            own[scene] = _parse(given)
        except DbenchInputError as exc:  # the refusal names the scope as given
            # "--scene-param: g given twice", "--scene-param g=nan: ...": after the scope
            said = str(exc).removeprefix("--scene-param")
            raise DbenchInputError(f"--scene-param {scene}:{said[1:]}") from None
        values_for(shared, own, scene)  # a name given for every scene and for this one
    return shared, own


def values_for(every: Mapping[str, str], own: Mapping[str, Mapping[str, str]],
               scene: str) -> dict[str, str]:
    """The values ``scene`` (as written) gets: ``every``'s and its own; DbenchInputError when
    one name has two values for it."""
    mine = dict(own.get(scene) or {})
    for name, value in mine.items():
        if name in every and str(every[name]) != str(value):
            raise DbenchInputError(
                f"--scene-param: {name} given twice for {scene}, {str(every[name])!r} (every "
                f"scene) and {str(value)!r} ({scene}:{name}={value}); give it once")
    return {**every, **mine}


def scene_of(name: str, every: Mapping[str, str], own: Mapping[str, Mapping[str, str]]):
    """The Scene ``name`` (as written: a catalogue name, scene file or folder) with the values
    it gets (:func:`values_for`), from the catalogue."""
    from .catalogue import get

    return get(name, values_for(every, own, name) or None)


def check_scopes(own: Mapping[str, Mapping[str, str]], scenes: Sequence[str],
                 option: str) -> None:
    """Refuse a scope that is none of ``scenes`` (a configuration built in Python, whose
    scopes :func:`split` did not read)."""
    for scene, values in own.items():
        if scene not in scenes:
            shown = ",".join(f"{k}={v}" for k, v in values.items())
            raise not_a_scene(f"{scene}:{shown}", scene, scenes, option)


def check_config(every: Mapping[str, str], own: Mapping[str, Mapping[str, str]],
                 scenes: Sequence[str], option: str) -> None:
    """Refuse what :func:`split` refuses of values given in Python: a scope that is none of
    ``scenes``, a name given two values for one scene."""
    check_scopes(own, scenes, option)
    for scene in scenes:
        values_for(every, own, scene)


__all__ = ["check_config", "check_scopes", "not_a_scene", "readings", "scene_of", "split",
           "values_for"]
