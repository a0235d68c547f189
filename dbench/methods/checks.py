"""Parameter checks shared by the methods: each raises DbenchInputError naming the parameter and
saying what it expected."""
from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

from ..errors import DbenchInputError


def check_radius(radius: Any, name: str = "radius") -> int:
    if isinstance(radius, bool) or not isinstance(radius, (int, np.integer)) or radius < 0:
        raise DbenchInputError(f"{name}: expected an integer ≥ 0, got {radius!r}")
    return int(radius)


def check_choice(name: str, value: Any, choices: Sequence[str]) -> str:
    if value not in choices:
        raise DbenchInputError(f"{name}: expected one of {list(choices)}, got {value!r}")
    return value


def check_features(value: Any, choices: Sequence[str], name: str = "features") -> None:
    """A guide's ``features``: one name or a sequence of names, each in ``choices``; anything
    else (a number, None, True) is refused naming ``name`` rather than failing inside the
    filter."""
    names = (value,) if isinstance(value, str) else value
    if not isinstance(names, (tuple, list)):
        raise DbenchInputError(f"{name}: expected a name or a sequence of names from "
                               f"{list(choices)}, got {value!r}")
    for f in names:
        check_choice(name, f, choices)


def check_positive(name: str, value: Any, *, allow_inf: bool = False, allow_zero: bool = False) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise DbenchInputError(f"{name}: expected a number, got {value!r}") from None
    if math.isnan(v) or (math.isinf(v) and not allow_inf) or v < 0 or (v == 0 and not allow_zero):
        kind = "≥ 0" if allow_zero else "> 0"
        raise DbenchInputError(f"{name}: expected a {'' if allow_inf else 'finite '}number {kind}, "
                               f"got {value!r}")
    return v
