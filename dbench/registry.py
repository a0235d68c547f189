"""The denoiser registry: look methods up by name (built-in methods and plugins).

:class:`~dbench.denoiser.Denoiser` and :func:`~dbench.denoiser.register` (the dictionary and the
decorator) live in :mod:`dbench.denoiser`, below :mod:`dbench.methods` and :mod:`dbench.plugins`;
they are re-exported here. Importing this module imports :mod:`dbench.methods`, so the built-in
methods are registered before any lookup and before any plugin (a plugin can never take a
built-in name: :func:`~dbench.denoiser.register` refuses a second class under one name).

Example:
    >>> from dbench.registry import register, Denoiser
    >>> @register("identity-example")
    ... class IdentityExample(Denoiser):
    ...     kinds = {"steady"}
    ...     needs = {"color"}
    ...     def denoise(self, data):
    ...         return data.color.copy()
"""
from __future__ import annotations

import re
from typing import Any

import numpy as np

from . import methods  # noqa: F401 - registers the built-in methods
from . import plugins
from .denoiser import (_REGISTRY, ALIASES, Denoiser, check_kinds, check_needs, defined_in,
                       register)
from .errors import DbenchInputError, UnknownNameError
from .methods.gate import SUFFIX, gated_class


def _load_plugins() -> None:
    """Plugins (entry points, ``DBENCH_PLUGINS``), once per process, after the built-in
    methods (imported with this module)."""
    plugins.ensure_loaded()


def available() -> list[str]:
    """Names of every registered method (built-in and plugins), sorted. The ``NAME+gate``
    variant of each steady method (:mod:`dbench.methods.gate`) is not listed; any of them
    resolves through :func:`method_class`."""
    _load_plugins()
    return sorted(_REGISTRY)


def canonical(name: str) -> str:
    """The name a method is published under: ``statistical-gate`` -> ``statistical+gate``."""
    return ALIASES.get(name, name)


def method_class(name: str) -> type[Denoiser]:
    """The class of ``name``: a registered method, an alias of one, or ``NAME+gate`` (the
    registered steady method ``NAME`` wrapped by ProDen's gate, :mod:`dbench.methods.gate`)."""
    if not isinstance(name, str):
        raise UnknownNameError(f"method: expected a name (str), got {name!r}; available "
                               f"methods: {', '.join(available())}")
    name = canonical(name)
    if name not in _REGISTRY:
        _load_plugins()
    if name.endswith(SUFFIX) and name not in _REGISTRY:
        try:
            base = method_class(name[:-len(SUFFIX)])
        except UnknownNameError as e:
            raise UnknownNameError(f"{name}: {e}") from None
        return gated_class(base)
    try:
        return _REGISTRY[name]
    except KeyError:
        why = plugins.broken_reason(name)
        if why:
            raise plugins.PluginError(why) from None
        # a plugin file that defines its class but forgot @register loads without a word:
        # say so where its method is asked for, or the user looks for a typo in the name
        empty = [p.name for p in plugins.all_plugins()
                 if p.ok and not p.provides and p.origin in ("--plugin", plugins.ENV_VAR)]
        hint = (f"; plugin {', '.join(empty)} loaded but registered no method (a Denoiser "
                f"subclass needs @register(\"NAME\"))" if empty else "")
        # an entry point naming a module: its name is the plugin's, not a method's
        named = [p for p in plugins.all_plugins() if p.ok and p.name == name and p.provides]
        hint += "".join(f"; plugin {p.name} ({p.origin}) registered {', '.join(p.provides)}, "
                        f"not a method named {name}" for p in named)
        raise UnknownNameError(
            f"unknown method {name!r}; available methods: {', '.join(available())} "
            f"(and NAME+gate for any steady method){hint}") from None


def get(name: str, **params: Any) -> Denoiser:
    """Build the method ``name`` with ``params`` overriding its defaults.

    A plugin's method that raises while it is built (its weights file is missing, its library
    is not installed) is a :class:`~dbench.plugins.PluginError` naming it and the reason, as a
    plugin that fails to load is (exit 2 before anything renders, README.md "Add your own
    denoiser"), not an internal error of dbench; dbench's own methods' errors pass unchanged.
    A parameter the method's constructor refuses (a :class:`~dbench.errors.DbenchInputError`,
    built-in method or plugin) is refused naming the method: ``jbf: sigma: expected 8 numbers
    ...``, so that a sweep over several methods says which one refused (README.md, "Usage")."""
    cls = method_class(name)

    def build():
        try:
            return cls(**params)
        except DbenchInputError as exc:
            raise _named(cls.name, exc) from None

    method = _plugin_call(cls, "could not be built", build)
    try:  # needs, kinds and version set in __init__ escape register()'s check of the class
        check_needs(cls.name, method.needs, method.optional_needs)
        check_kinds(cls.name, method.kinds)
        mine = vars(method).get("version", getattr(cls, "version", None))
        if mine != getattr(cls, "version", None):  # a result's identity would not hold it
            raise ValueError(f"version {mine!r} set in __init__ is not read: a result's "
                             f"identity holds the class attribute version; set it there")
    except ValueError as exc:
        raise plugins.PluginError(f"method {cls.name} ({defined_in(cls)}) could not be built: "
                                  f"{exc}") from None
    return method


def applies(method: Denoiser, kind: str, available: set[str] | None = None
            ) -> tuple[bool, str]:
    """``method.applies_to(kind, available)``: (ok, the reason of a skip). A plugin's
    ``applies_to`` that raises, or answers anything but a bool and a string, is a
    :class:`~dbench.plugins.PluginError` naming the method and what went wrong, as a method that
    cannot be built is (:func:`get`): exit 2 before anything renders where ``run`` and
    ``sweep`` ask it first, the method's failure where a cell asks it (README.md "Add your own
    denoiser"); dbench's own methods' errors pass unchanged."""
    cls = type(method)
    answer = _plugin_call(cls, f"failed in applies_to({kind!r})",
                          lambda: method.applies_to(kind, available))
    if _own(cls):
        return answer
    # `ok, why = answer` would fail on None or True with an error of Python's, not the plugin's
    if not (isinstance(answer, tuple) and len(answer) == 2
            and isinstance(answer[0], (bool, np.bool_)) and isinstance(answer[1], str)):
        raise plugins.PluginError(
            f"method {cls.name} ({defined_in(cls)}): applies_to({kind!r}) returned "
            f"{' '.join(repr(answer).split())[:80]}; expected (ok, reason): True or False and "
            f"a string")
    return bool(answer[0]), answer[1]


def wants(method: Denoiser, available: set[str] | frozenset[str]) -> set[str]:
    """``method.wants(available)``: the buffers to load for it (a set of buffer names). A
    plugin's ``wants`` that raises, or answers anything but a set (or frozenset) of strings, is
    a :class:`~dbench.plugins.PluginError` naming the method and what went wrong, as in
    :func:`applies` (README.md "Add your own denoiser"); dbench's own methods' errors pass
    unchanged."""
    cls = type(method)
    answer = _plugin_call(cls, f"failed in wants({sorted(available)})",
                          lambda: method.wants(available))
    if _own(cls):
        return answer
    if not (isinstance(answer, (set, frozenset)) and all(isinstance(b, str) for b in answer)):
        raise plugins.PluginError(
            f"method {cls.name} ({defined_in(cls)}): wants() returned "
            f"{' '.join(repr(answer).split())[:80]}; expected a set of buffer names")
    return set(answer)


def _named(name: str, exc: DbenchInputError) -> DbenchInputError:
    """``exc``, its message led by the method's ``name`` (``jbf: sigma: ...``) unless it
    already starts with it (``nca.weights: ...``, ``statistical: ...``); of its own type where
    its message is its one argument, else a :class:`~dbench.errors.DbenchInputError`."""
    text = str(exc)
    if re.match(rf"{re.escape(name)}(?![\w+-])", text):
        return exc
    if exc.args == (text,):
        exc.args = (f"{name}: {text}",)
        return exc
    return DbenchInputError(f"{name}: {text}")


def _own(cls: type) -> bool:
    """Whether ``cls`` is one of dbench's own methods (its errors are dbench's to report)."""
    return cls.__module__.split(".")[0] == "dbench"


def _plugin_call(cls: type, what: str, call):
    """``call()`` (building, or asking, a method of class ``cls``): a plugin's own failure in
    it is a :class:`~dbench.plugins.PluginError` naming the method, where it is defined and
    ``what`` failed, in one line (README.md "Add your own denoiser"); dbench's own methods'
    errors, and a refusal of the user's input, pass unchanged."""
    try:
        return call()
    except DbenchInputError:
        raise
    except Exception as exc:  # noqa: BLE001 - named below, when it is a plugin's own code
        if _own(cls):
            raise
        raise plugins.PluginError(f"method {cls.name} ({defined_in(cls)}) {what}: "
                                  f"{plugins.one_line(exc)}") from exc


__all__ = ["ALIASES", "Denoiser", "register", "available", "canonical", "method_class", "get",
           "applies", "wants"]
