"""The denoiser registry: look methods up by name (built-in methods and plugins).

:class:`~dbench.denoiser.Denoiser` and :func:`~dbench.denoiser.register` (the dictionary and the
decorator) live in :mod:`dbench.denoiser`, below :mod:`dbench.plugins`; they are re-exported here.

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

from typing import Any

from . import plugins
from .denoiser import _REGISTRY, Denoiser, register
from .errors import UnknownNameError


def _load_plugins() -> None:
    """Built-in methods, then plugins (entry points, ``DBENCH_PLUGINS``), once per process."""
    plugins.ensure_loaded()


def available() -> list[str]:
    """Names of every registered method (built-in and plugins), sorted."""
    _load_plugins()
    return sorted(_REGISTRY)


def method_class(name: str) -> type[Denoiser]:
    if name not in _REGISTRY:
        _load_plugins()
    try:
        return _REGISTRY[name]
    except KeyError:
        why = plugins.broken_reason(name)
        if why:
            raise plugins.PluginError(why) from None
        raise UnknownNameError(
            f"unknown method {name!r}; available methods: {', '.join(available())}") from None


def get(name: str, **params: Any) -> Denoiser:
    """Build the method ``name`` with ``params`` overriding its defaults."""
    return method_class(name)(**params)


__all__ = ["Denoiser", "register", "available", "method_class", "get"]
