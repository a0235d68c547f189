"""Image sizes: ``Res(width, height)``, parsed from ``256``, ``"160x90"`` or ``(160, 90)``.

Every render takes a :class:`Res`. Square sizes keep the integer form in cache keys, file names
and tables (``res`` = 256), so results rendered before non-square sizes existed keep their
identity; other sizes are written ``"WxH"`` (``"160x90"``).

Field of view: the catalogue's cameras state it along x. A square image is unchanged; a
non-square one keeps that angle along its smaller side (Mitsuba's ``fov_axis = "smaller"``), so
a wide image shows the square view plus more on the left and right, and a tall one more above
and below; the view is never cropped.

Example:
    >>> parse_res("160x90")
    Res(width=160, height=90)
    >>> parse_res(64).key, parse_res("160x90").key
    (64, '160x90')
"""
from __future__ import annotations

import math
import re
from typing import Any, NamedTuple

import numpy as np

from .errors import DbenchInputError

#: Largest image side dbench renders (memory of one film and its statistics).
MAX_SIDE = 4096


class Res(NamedTuple):
    """An image size in pixels."""

    width: int
    height: int

    @property
    def square(self) -> bool:
        return self.width == self.height

    @property
    def key(self) -> int | str:
        """The form used in cache keys, meta, tables and file names: the side for a square
        image, else ``"WxH"``."""
        return self.width if self.square else f"{self.width}x{self.height}"

    @property
    def pixels(self) -> int:
        return self.width * self.height

    @property
    def fov_axis(self) -> str:
        """Mitsuba's ``fov_axis`` that keeps a square view's angle (module docstring):
        ``x`` for a square image (the catalogue's historical value), ``smaller`` otherwise."""
        return "x" if self.square else "smaller"

    @property
    def text(self) -> str:
        """``"256×256"``: for titles and reports."""
        return f"{self.width}×{self.height}"

    def __str__(self) -> str:
        return str(self.key)


class Resolution(int):
    """The size a scene's ``build(mi, res)`` receives (README.md, "Python scene files"): an
    ``int`` equal to the width, so code written when ``res`` was one side (``"width": res,
    "height": res``) still gives square films, with ``width`` and ``height`` attributes, and it
    unpacks as ``width, height = res``.

        >>> r = Resolution(160, 90)
        >>> int(r), r.width, r.height, tuple(r), str(r)
        (160, 160, 90, (160, 90), '160x90')
    """

    def __new__(cls, width: int, height: int) -> "Resolution":
        obj = super().__new__(cls, int(width))
        obj._height = int(height)
        return obj

    @property
    def width(self) -> int:
        return int(self)

    @property
    def height(self) -> int:
        return self._height

    @property
    def res(self) -> Res:
        return Res(int(self), self._height)

    # the Res properties, so code written for a Res keeps working
    square = property(lambda self: self.res.square)
    key = property(lambda self: self.res.key)
    pixels = property(lambda self: self.res.pixels)
    fov_axis = property(lambda self: self.res.fov_axis)
    text = property(lambda self: self.res.text)

    def __iter__(self):
        return iter(self.res)

    def __len__(self) -> int:
        return 2

    def __getitem__(self, i):
        return self.res[i]

    def __eq__(self, other: object) -> bool:
        if isinstance(other, Resolution):
            return self.res == other.res
        return int.__eq__(self, other)

    def __ne__(self, other: object) -> bool:
        eq = self.__eq__(other)
        return eq if eq is NotImplemented else not eq

    __hash__ = int.__hash__

    def __repr__(self) -> str:
        return f"Resolution(width={int(self)}, height={self._height})"

    def __str__(self) -> str:
        return str(self.key)

    def __reduce__(self):
        return (Resolution, (int(self), self._height))

    @classmethod
    def of(cls, value: Any) -> "Resolution":
        """``value`` (any form :func:`parse_res` takes) as a Resolution."""
        r = parse_res(value)
        return cls(r.width, r.height)


def size_text(value: Any) -> str:
    """``"W×H"`` of a size in any form :func:`parse_res` takes (e.g. a table's ``res`` cell);
    the value itself as text when it is not one."""
    try:
        return parse_res(value).text
    except DbenchInputError:
        return str(value)


_WXH = re.compile(r"^\s*(\d+)\s*[xX×]\s*(\d+)\s*$")


def parse_res(value: Any, name: str = "res") -> Res:
    """``value`` as a :class:`Res`: an integer side N (N × N), ``"N"``, ``"WxH"``, a (width,
    height) pair or a Res. Anything else, a side < 1 or > MAX_SIDE: a DbenchInputError naming
    ``name`` and the valid forms."""
    valid = "an integer side such as 256, or WIDTHxHEIGHT such as 1280x720"
    if isinstance(value, Resolution):  # before the int branch: it is an int (the width)
        w, h = value.width, value.height
    elif isinstance(value, Res):
        w, h = value
    elif isinstance(value, (bool, np.bool_)):
        raise DbenchInputError(f"{name}: expected {valid}, got {value!r}")
    elif isinstance(value, (int, np.integer)):
        w = h = int(value)
    elif isinstance(value, str):
        m = _WXH.match(value)
        if m:
            w, h = int(m.group(1)), int(m.group(2))
        elif value.strip().isdigit():
            w = h = int(value)
        else:
            raise DbenchInputError(f"{name}: expected {valid}, got {value!r}")
    elif isinstance(value, (tuple, list)) and len(value) == 2 and all(
            isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_))
            for v in value):
        w, h = int(value[0]), int(value[1])
    else:
        raise DbenchInputError(f"{name}: expected {valid}, got {value!r}")
    if w < 1 or h < 1:
        raise DbenchInputError(f"{name}: width and height must be >= 1, got {w}x{h}")
    if max(w, h) > MAX_SIDE:
        raise DbenchInputError(f"{name}: {w}x{h} is above the largest supported side "
                               f"{MAX_SIDE}")
    return Res(int(w), int(h))


#: sensors that take a field of view (and so a ``fov_axis``)
FOV_SENSORS = ("perspective", "thinlens")


def focal_fov(focal: Any, film: Any) -> float:
    """The field of view along x, in degrees, of a 35 mm-equivalent ``focal_length`` (``"50mm"``
    or a number of mm) on ``film`` (a film dictionary; hdrfilm's 768×576 where it gives no
    size), as Mitsuba computes it: the angle across the 36×24 mm diagonal, then along x for
    the film's aspect."""
    text = str(focal).strip().lower().removesuffix("mm")
    try:
        f = float(text)
    except ValueError:
        raise DbenchInputError(f"sensor: focal_length {focal!r}; give a number of mm such "
                               f"as \"50mm\" or a \"fov\" in degrees") from None
    if not math.isfinite(f) or f <= 0:
        raise DbenchInputError(f"sensor: focal_length {focal!r} must be > 0 mm")
    film = film if isinstance(film, dict) else {}
    w, h = float(film.get("width", 768)), float(film.get("height", 576))
    tan_half_diagonal = math.hypot(36.0, 24.0) / (2.0 * f)
    return math.degrees(2.0 * math.atan(tan_half_diagonal * w / math.hypot(w, h)))


__all__ = ["Res", "Resolution", "parse_res", "size_text", "MAX_SIDE", "FOV_SENSORS", "focal_fov"]
