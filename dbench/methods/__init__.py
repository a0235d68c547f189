"""Registered denoisers. Importing this package registers every built-in method.

    >>> from dbench import methods
    >>> "noisy" in methods.available()
    True
"""
from importlib import import_module

from ..registry import Denoiser, available, get, method_class, register

_BUILTIN = ("noisy", "oidn")
for _name in _BUILTIN:
    import_module(f"{__name__}.{_name}")

__all__ = ["Denoiser", "available", "get", "method_class", "register"]
