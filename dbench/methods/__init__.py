"""Registered denoisers. Importing this package registers every built-in method: each
sub-package of ``dbench/methods/`` registers itself with ``@register`` when imported. Methods from
outside (entry points ``dbench.methods``, ``$DBENCH_PLUGINS``, ``--plugin``) are loaded by
:mod:`dbench.plugins` on the first lookup, after these.

    >>> from dbench import methods
    >>> "noisy" in methods.available()
    True
"""
import pkgutil
from importlib import import_module

from ..registry import Denoiser, available, get, method_class, register

for _info in pkgutil.iter_modules(__path__):
    if _info.ispkg:
        import_module(f"{__name__}.{_info.name}")

__all__ = ["Denoiser", "available", "get", "method_class", "register"]
