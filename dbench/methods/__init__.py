"""Registered denoisers. Importing this package registers every built-in method: each
sub-package of ``dbench/methods/`` registers itself with ``@register`` (:mod:`dbench.denoiser`)
when imported. Lookups by name (:mod:`dbench.registry`, which imports this package) find them,
then the methods from outside (entry points ``dbench.methods``, ``$DBENCH_PLUGINS``,
``--plugin``, loaded by :mod:`dbench.plugins` on the first lookup, after these).

    >>> from dbench import registry
    >>> "noisy" in registry.available()
    True
"""
import pkgutil
from importlib import import_module

for _info in pkgutil.iter_modules(__path__):
    if _info.ispkg:
        import_module(f"{__name__}.{_info.name}")

