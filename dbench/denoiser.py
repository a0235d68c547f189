"""The method base class and the registry it goes into: a dictionary and a decorator, as timm
registers models. Lookups (``get``, ``available``, ``method_class``, which also load plugins)
are in :mod:`dbench.registry`.

Example:
    >>> from dbench.denoiser import register, Denoiser
    >>> @register("identity-example")
    ... class IdentityExample(Denoiser):
    ...     kinds = {"steady"}
    ...     needs = {"color"}
    ...     def denoise(self, data):
    ...         return data.color.copy()
"""
from __future__ import annotations

import inspect
import math
import re
from typing import Any, Callable

import numpy as np

from .data import BUFFER_NAMES
from .errors import DbenchInputError

_REGISTRY: dict[str, type["Denoiser"]] = {}

#: The data a method can take (README.md, "Add your own denoiser": ``kinds``).
KINDS = ("steady", "sequence", "transient")
#: The suffix of a steady method wrapped by ProDen's gate (:mod:`dbench.methods.gate`).
GATE_SUFFIX = "+gate"
#: Old names kept working: name -> the name it now has (:func:`dbench.registry.canonical`).
ALIASES = {"statistical-gate": "statistical+gate"}
#: A name a user can type: method lists split at commas (``--method a,b``), a label adds
#: ``[key=value]`` to the name (``jbf[radius=3]``) and ``all`` stands for every method.
_NAME = re.compile(r"[^\W_][\w.+-]*")


def check_method_name(name: Any) -> None:
    """Refuse (ValueError) a method name that could not be asked for or would stand for another
    method: anything but letters, digits and ``_ . + -`` (a comma, a space, a bracket, ``=``),
    ``all``, an old name of a built-in method, or ``NAME+gate`` (the gated ``NAME``)."""
    if not isinstance(name, str) or not _NAME.fullmatch(name):
        raise ValueError(f"method name {name!r}: expected letters, digits and _ . + - "
                         f"(starting with a letter or a digit)")
    if name == "all" or name in ALIASES or name.endswith(GATE_SUFFIX):
        what = ("'all' stands for every method" if name == "all" else
                f"{name!r} is the old name of {ALIASES[name]}" if name in ALIASES else
                f"NAME{GATE_SUFFIX} is the method NAME wrapped by ProDen's gate")
        raise ValueError(f"method name {name!r} is taken: {what}")


def check_like_default(name: str, value: Any, default: Any) -> None:
    """Refuse a parameter value of another kind than its default's, before anything renders: a
    bool default takes True or False only (a string such as ``false`` from the command line
    would read as true), an integer default an integer (2.7 would be truncated), a float
    default a number that is not NaN. Defaults of other kinds (None, strings) are the
    method's to check."""
    real = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(
        value, (bool, np.bool_))
    if isinstance(default, bool):
        if not isinstance(value, (bool, np.bool_)):
            raise DbenchInputError(f"{name}: expected True or False, got {value!r}")
    elif isinstance(default, int):
        if not real or not float(value).is_integer():
            raise DbenchInputError(f"{name}: expected an integer, got {value!r}")
    elif isinstance(default, float):
        if not real or math.isnan(value):
            raise DbenchInputError(f"{name}: expected a number, got {value!r}")


def is_identity_value(value: Any) -> bool:
    """Whether ``value`` reads back the same from a sweep cell's identity (JSON): None, a bool,
    an int, a float other than NaN (NaN equals nothing, so a method run with its defaults would
    be labelled as if it were not), a string, or a list, tuple or str-keyed dict of them. A
    function or an object is written as its repr, which holds its address and so changes in
    every process: a sweep would call its own cells changed."""
    if value is None or isinstance(value, (bool, int, str)):
        return True
    if isinstance(value, float):
        return not math.isnan(value)
    if isinstance(value, (list, tuple)):
        return all(is_identity_value(v) for v in value)
    if isinstance(value, dict):
        return all(isinstance(k, str) and is_identity_value(v) for k, v in value.items())
    return False


class Denoiser:
    """Base class of every method.

    Class attributes a method sets:
        kinds: the Dataset kinds it accepts (``steady``, ``sequence``, ``transient``).
        needs: the buffers it cannot run without (names from :data:`dbench.data.BUFFER_NAMES`).
            Where they depend on parameters, ``__init__`` sets ``self.needs`` from the
            resolved ones (``oidn`` with ``features=none`` needs the colour alone), and
            :meth:`applies_to` and :meth:`wants` read the instance's; the class attribute is
            the default parameters' needs, the one ``dbench list`` shows.
        optional_needs: buffers it uses when the data has them and runs without otherwise
            (its docstring says what changes); loaded wherever the scene provides them.
        defaults: parameter defaults; ``get(name, **params)`` overrides them.
        keeps_emitters: True when ``denoise`` already hands the lights of the ``emitter`` buffer
            back to the input (:func:`dbench.methods.kernels.emitters.keep_emitters`), so that
            a wrapper such as ``NAME+gate`` does not apply the rule a second time.

    Sequence methods keep state: call ``reset()`` and then ``denoise(frame)`` per frame in order.
    ``denoise`` returns float32 with the shape of ``data.color``, finite wherever it is finite.
    """

    name: str = ""
    kinds: set[str] = {"steady"}
    needs: set[str] = {"color"}
    optional_needs: set[str] = set()
    defaults: dict[str, Any] = {}
    keeps_emitters: bool = False
    #: What ``denoise_device`` runs on (``"triton"``, ``"torch"``, ``"oidn-cuda"`` …), recorded
    #: with every result it produces; "" for a method without a device path.
    device_backend: str = ""

    def __init__(self, **params: Any) -> None:
        unknown = set(params) - set(self.defaults)
        if unknown:
            raise DbenchInputError(
                f"{self.name}: unknown parameter(s) {sorted(unknown)}; "
                f"valid: {sorted(self.defaults) or 'none'}")
        for key, value in params.items():
            check_like_default(key, value, self.defaults[key])
        self.params: dict[str, Any] = {**self.defaults, **params}

    def reset(self) -> None:
        """Forget any state kept across frames (no-op for single-frame methods)."""

    def denoise(self, data: Any) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def check_input(self, data: Any) -> None:
        """Refuse ``data`` that is not a dbench frame of a kind this method takes (a
        :class:`~dbench.data.Frame`, also one frame of a sequence for a temporal method, or a
        :class:`~dbench.data.TransientFrame`), naming the method and what it takes, so a bare
        array is one DbenchInputError rather than an AttributeError from inside the method."""
        takes = set(self.kinds) | ({"steady"} if "sequence" in self.kinds else set())
        kind = getattr(data, "kind", None)
        if kind not in takes or not hasattr(data, "color"):
            names = {"steady": "Frame", "sequence": "Frame", "transient": "TransientFrame"}
            wanted = dict.fromkeys(names[k] for k in sorted(self.kinds) if k in names)
            raise DbenchInputError(
                f"{self.name}: expected a dbench {' or '.join(wanted)}, got "
                f"{kind + ' data' if isinstance(kind, str) else type(data).__name__}")

    def denoise_device(self, data: Any) -> Any:  # pragma: no cover - optional
        """The method on a :class:`dbench.device.DeviceFrame` whose buffers are tensors already
        on a device: returns an (H, W, 3) float32 tensor on that device, the same numbers as
        ``denoise`` within the tolerance its tests state, with no NumPy conversion inside the
        call and any history kept on the device (docs/gpu.md)."""
        raise NotImplementedError

    @classmethod
    def has_device_path(cls) -> bool:
        """Whether the method implements :meth:`denoise_device`."""
        return cls.denoise_device is not Denoiser.denoise_device

    def runs_on_device(self) -> bool:
        """Whether this instance, with its parameters, runs :meth:`denoise_device` (a method
        whose device path covers only some settings says no for the others, which then run
        on the host and are recorded as such)."""
        return self.has_device_path()

    def applies_to(self, kind: str, available: set[str] | None = None) -> tuple[bool, str]:
        """Whether the method can run on a dataset of ``kind`` offering ``available`` buffers.

        Returns (ok, reason); the reason explains a skip in reports.
        """
        if kind not in self.kinds and not self.per_frame(kind):
            why = f"{self.name} works on {sorted(self.kinds)}, not on {kind} data"
            others = counterparts(self.name, kind)
            return False, why + (f"; on {kind} data: {', '.join(others)}" if others else "")
        if available is not None:
            missing = set(self.needs) - set(available)
            if missing:
                return False, f"{self.name} needs {sorted(missing)}, which the scene cannot provide"
        return True, ""

    def wants(self, available: set[str] | frozenset[str]) -> set[str]:
        """The buffers to load for this method from a scene offering ``available``: ``needs``
        and whichever ``optional_needs`` are there."""
        return set(self.needs) | (set(self.optional_needs) & set(available))

    def per_frame(self, kind: str) -> bool:
        """Whether the method runs on ``kind`` data as a single-frame method: a steady method on
        a sequence denoises every frame alone (``reset()`` before each frame, no history), so
        sequence tables hold single-frame and temporal methods side by side."""
        return kind == "sequence" and "sequence" not in self.kinds and "steady" in self.kinds

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.params})"


def counterparts(name: str, kind: str) -> list[str]:
    """The registered methods that do what ``name`` does on ``kind`` data, by the naming the
    built-in methods follow (``jbf-bins`` and ``oidn-bins``: ``jbf`` and ``oidn`` on every time
    bin of a transient video; README.md, "Methods"), sorted: what a skip reason points to."""
    return sorted(n for n, cls in _REGISTRY.items()
                  if n.startswith(name + "-") and kind in getattr(cls, "kinds", ()))


def check_needs(name: str, needs: Any, optional_needs: Any) -> None:
    """Refuse (ValueError) ``needs`` or ``optional_needs`` naming a buffer outside
    :data:`~dbench.data.BUFFER_NAMES`, which would skip the method on every scene, or the
    reference, which no method is handed (dbench/run/inputs.py): a class's when it is
    registered, an instance's when it is built (:func:`dbench.registry.get`: needs set in
    ``__init__``)."""
    asked = set(needs) | set(optional_needs)
    bad = asked - set(BUFFER_NAMES)
    if bad:
        raise ValueError(f"method {name!r} needs unknown buffers {sorted(bad)}; valid: "
                         f"{', '.join(b for b in BUFFER_NAMES if b != 'reference')}")
    if "reference" in asked:
        raise ValueError(f"method {name!r} needs the reference: it is what a method is "
                         f"scored against, and no method is handed it (dbench/run/inputs.py)")


def check_kinds(name: str, kinds: Any) -> None:
    """Refuse (ValueError) ``kinds`` that are no non-empty set of :data:`KINDS`: ``"steady"``
    would read as its letters, and a misspelt kind would skip the method on every scene
    without a word about the typo; a class's when it is registered, an instance's when it is
    built (:func:`dbench.registry.get`: kinds set in ``__init__``)."""
    if isinstance(kinds, str) or not isinstance(kinds, (set, frozenset, list, tuple)) \
            or not kinds or not set(kinds) <= set(KINDS):
        raise ValueError(f"method {name!r}: kinds {kinds!r}; expected a non-empty set "
                         f"of {', '.join(KINDS)}")


def defined_in(cls: type) -> str:
    """Where ``cls`` was written: its file, else its module's name (a class typed in
    ``python -c`` or a notebook has no file; a ``--plugin`` file's module name is dbench's)."""
    try:
        return inspect.getfile(cls)
    except (TypeError, OSError):
        return cls.__module__


def register(name: str) -> Callable[[type[Denoiser]], type[Denoiser]]:
    """Class decorator adding a Denoiser subclass to the registry under ``name``.

    Refuses (ValueError; a plugin that raises it is *broken*, with the reason) what README.md
    "Add your own denoiser" rules out: a name taken or one that could not be asked for, a
    class registered under another name already, needs
    outside :data:`~dbench.data.BUFFER_NAMES` or naming the reference, kinds outside
    :data:`KINDS`, a ``version`` that is no string or number, and defaults that are no dict of
    :func:`is_identity_value` values."""

    def wrap(cls: type[Denoiser]) -> type[Denoiser]:
        check_method_name(name)
        if name in _REGISTRY and _REGISTRY[name] is not cls:
            # two files of one name (a/same.py, b/same.py) could not be told apart otherwise
            held = _REGISTRY[name]
            raise ValueError(f"method {name!r} is already registered by {held.__qualname__} "
                             f"({defined_in(held)})")
        other = [n for n, c in _REGISTRY.items() if c is cls and n != name]
        if other:  # cls.name would become the last name, and the first would run under it
            raise ValueError(f"method {name!r}: {cls.__qualname__} ({defined_in(cls)}) is "
                             f"registered as {other[0]!r} already; a class has one name "
                             f"(register a subclass under the second)")
        check_needs(name, cls.needs, cls.optional_needs)
        check_kinds(name, cls.kinds)
        version = getattr(cls, "version", None)  # a class attribute, part of the identity
        if version is not None and (isinstance(version, bool)
                                    or not isinstance(version, (str, int, float))):
            raise ValueError(f"method {name!r}: version {version!r}; expected a class "
                             f"attribute holding a string or a number (a property or an "
                             f"object is written with its address, another in every process)")
        if not isinstance(cls.defaults, dict):  # read as a dict when the method is built
            raise ValueError(f"method {name!r}: defaults {cls.defaults!r}; expected a dict "
                             f"of parameter names and their defaults")
        for key, value in cls.defaults.items():  # part of a sweep cell's identity
            if not isinstance(key, str) or not is_identity_value(value):
                raise ValueError(f"method {name!r}: default {key!r}={value!r}; expected None, "
                                 f"True/False, a Python number (not NaN), a string, or a list or "
                                 f"dict of them (the defaults are part of a result's identity)")
        cls.name = name
        _REGISTRY[name] = cls
        return cls

    return wrap
