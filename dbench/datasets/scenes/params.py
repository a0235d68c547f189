"""Declared parameters of catalogue scenes: ``--scene-param NAME=VALUE`` on ``dbench run``,
``sweep``, ``render`` and ``export``.

A catalogue scene declares its parameters (``Scene.declared``: name, type, default, valid range
or choices) and a ``Scene.variant`` function that builds the scene of one set of values.
:func:`bind` checks every given value before anything renders: an unknown name or a bad value
raises :class:`~dbench.errors.DbenchInputError` with one line naming the parameter and the
valid choices (the command line exits 2).

Identity: the bound scene keeps the catalogue name and carries every declared value in
``Scene.params``, which enters the cache keys and :func:`dbench.datasets.scene_fingerprint`
(hence sweep cell identities), so a cached render is reused only for the same values. Values
equal to the defaults give back the catalogue scene itself (the same cache entries as without
``--scene-param``). The same values give the same object, so the in-process caches of loaded
scenes are shared.

Example:
    >>> sc = bind(scenes.get("fog-transient"), {"g": "-0.3"})          # doctest: +SKIP
    >>> sc.params["g"], sc.params["sigma_s"]                             # doctest: +SKIP
    (-0.3, 0.6)
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from ...errors import DbenchInputError


@dataclass(frozen=True)
class Param:
    """One declared parameter: a number in [lo, hi] (ends excluded where ``open_lo`` /
    ``open_hi``) or, when ``choices`` is given, one of those words."""

    name: str
    default: Any
    doc: str = ""
    choices: tuple[str, ...] = ()
    lo: float = -math.inf
    hi: float = math.inf
    open_lo: bool = False
    open_hi: bool = False

    def valid(self) -> str:
        """The valid values as text: ``pulse|step`` or ``-1 < x < 1``."""
        if self.choices:
            return "|".join(self.choices)
        lo = f"{self.lo:g} {'<' if self.open_lo else '≤'} " if math.isfinite(self.lo) else ""
        hi = f" {'<' if self.open_hi else '≤'} {self.hi:g}" if math.isfinite(self.hi) else ""
        return f"{lo}x{hi}"

    def describe(self) -> str:
        return f"{self.name} ({self.valid()}, default {self.default})"

    def parse(self, scene: str, text: str) -> Any:
        """The value of ``text``; DbenchInputError (one line) when it is not valid."""
        where = f"--scene-param {self.name}={text}: {scene}'s {self.doc or self.name}"
        if self.choices:
            value = str(text).strip()
            if value not in self.choices:
                raise DbenchInputError(f"{where} is one of {self.valid()}")
            return value
        try:
            value = float(text)
        except (TypeError, ValueError):
            value = math.nan
        inside = (math.isfinite(value)
                  and (value > self.lo if self.open_lo else value >= self.lo)
                  and (value < self.hi if self.open_hi else value <= self.hi))
        if not inside:
            raise DbenchInputError(f"{where} is a number {self.valid()}")
        return value


def describe_all(declared) -> str:
    return "; ".join(p.describe() for p in declared)


def check(scene, given: dict[str, str]) -> dict[str, Any]:
    """Every declared value of ``scene`` with ``given`` (text) applied, checked."""
    by_name = {p.name: p for p in scene.declared}
    for name in given:
        if name not in by_name:
            raise DbenchInputError(f"--scene-param {name}: {scene.name} has no parameter "
                                   f"{name!r}; valid: {describe_all(scene.declared)}")
    return {p.name: (p.parse(scene.name, given[p.name]) if p.name in given else p.default)
            for p in scene.declared}


_BOUND: dict[tuple, Any] = {}


def bind(scene, given: dict[str, str] | None):
    """The scene of ``scene`` (a catalogue entry) with the ``--scene-param`` values ``given``
    ({name: text}): the catalogue scene itself when nothing differs from the defaults, else
    ``scene.variant(scene, values)`` (memoised: the same values give the same object)."""
    if not given:
        return scene
    if not scene.declared or scene.variant is None:
        from .record import _CATALOGUE

        takers = sorted(n for n, s in _CATALOGUE.items() if s.declared)
        raise DbenchInputError(f"--scene-param: {scene.name} is a catalogue scene without "
                               f"parameters; parameters apply to scene files and to the "
                               f"scenes that declare them ({', '.join(takers) or 'none'})")
    values = check(scene, given)
    if all(values[p.name] == p.default for p in scene.declared):
        return scene
    key = (scene.name, id(scene), tuple(sorted(values.items())))
    if key not in _BOUND:
        _BOUND[key] = scene.variant(scene, values)
    return _BOUND[key]


def non_default(scene, values: dict[str, Any]) -> dict[str, Any]:
    """The values that differ from ``scene``'s declared defaults, in declaration order."""
    return {p.name: values[p.name] for p in scene.declared
            if p.name in values and values[p.name] != p.default}


__all__ = ["Param", "bind", "check", "describe_all", "non_default"]
