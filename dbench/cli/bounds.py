"""Bounds of the count options, checked before a command does anything.

Counts (``--spp``, ``--ref-spp``, ``--frames``, ``--bins``, ``--seeds``, ``--repeats``) are
integers in [1, :data:`MAX_COUNT`] (``--ref-spp`` in [2, :data:`MAX_COUNT`]: :func:`ref_count`);
``1e3`` is read as 1000. The other integer options are
read by :func:`integer` and the real-valued ones by :func:`number` (finite), so that ``--lam
abc`` is one line too. Anything else (``--ref-spp 1e20``,
``--spp 0``, ``--bins many``) is refused before the command resolves a scene or renders, with
one line naming the option and the valid range, exit 2, as every other bad input
(dbench/cli/__init__.py). ``--bins`` is further bounded by the memory of the transient film at
the run's size (:func:`dbench.datasets.transient.scene.check_bins`, called by
:func:`dbench.cli.args._check_common`); sizes are checked by :func:`dbench.resolution.parse_res`.

argparse's own refusal of a ``type`` is a usage line and an error line raised as SystemExit, so
:func:`count` never refuses: it returns a :class:`BadCount`, which :func:`check_counts` turns
into the one-line DbenchInputError as the command starts (:func:`dbench.cli.guard.command`).
"""
from __future__ import annotations

import argparse
import math

from ..data import MAX_COUNT  # the largest count an option takes
from ..errors import DbenchInputError


def parse_count(text: str, top: int = MAX_COUNT) -> int:
    """``text`` as an int in [1, top]: an integer, or a number written with an exponent whose
    value is a whole number (``1e3``). ValueError saying the valid range otherwise."""
    value: int | None = None
    t = str(text).strip()
    try:
        value = int(t)
    except ValueError:
        try:
            f = float(t)
        except ValueError:
            f = math.nan
        if math.isfinite(f) and f == int(f):
            value = int(f)
    if value is None or not 1 <= value <= top:
        raise ValueError(f"expected an integer in [1, {top}], got {str(text)!r}")
    return value


class BadCount(str):
    """The text of a count option that is not one, with ``why``."""

    why = ""


def count(text: str) -> int | BadCount:
    """argparse ``type`` of the count options: the int, or a :class:`BadCount`."""
    try:
        return parse_count(text)
    except ValueError as exc:
        bad = BadCount(text)
        bad.why = str(exc)
        return bad


def ref_count(text: str) -> int | BadCount:
    """argparse ``type`` of ``--ref-spp``: a count of at least 2
    (:func:`dbench.datasets.references.ref_spp_problem`), or a :class:`BadCount`."""
    from ..datasets.references import ref_spp_problem

    value = count(text)
    if isinstance(value, BadCount) or ref_spp_problem(value):
        bad = BadCount(text)
        bad.why = ref_spp_problem(value if not isinstance(value, BadCount) else str(text))
        return bad
    return value


def integer(text: str) -> int | BadCount:
    """argparse ``type`` of the other integer options (``--width``, ``--workers``, ``--steps``):
    the int (its range is checked where it is used), or a :class:`BadCount`."""
    try:
        return int(str(text).strip())
    except ValueError:
        bad = BadCount(text)
        bad.why = f"expected an integer, got {str(text)!r}"
        return bad


def number(text: str) -> float | BadCount:
    """argparse ``type`` of the real-valued options (``--lam``, ``--minutes``): a finite float,
    or a :class:`BadCount`."""
    try:
        value = float(str(text).strip())
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        bad = BadCount(text)
        bad.why = f"expected a finite number, got {str(text)!r}"
        return bad
    return value


def check_counts(args: argparse.Namespace) -> None:
    """A DbenchInputError naming the first count option of ``args`` that is a BadCount."""
    for dest, value in vars(args).items():
        if isinstance(value, BadCount):
            raise DbenchInputError(f"--{dest.replace('_', '-')}: {value.why}")


__all__ = ["MAX_COUNT", "parse_count", "count", "integer", "number", "BadCount", "check_counts"]
