"""What every command runs inside (set by :func:`dbench.cli.parser.build_parser`): options
given an empty value refused, the count options checked first (:mod:`dbench.cli.bounds`),
``--cache`` with ``--no-cache`` refused, and no exit code but dbench's own.

A plugin's method, a scene file or a plugin scene is code from outside dbench; where dbench
calls it, a ``sys.exit`` becomes a failure it reports itself (the method's row of a run, a
broken plugin, a scene file that does not load). Anywhere else the command stops with one line
naming the file and line that called it, exit 2 (README.md, "Python scene files"), never the
caller's own code: a ``sys.exit(0)`` must not look like a finished run.
"""
from __future__ import annotations

import argparse
import functools
import traceback
from typing import Callable

from ..errors import DbenchInputError
from .bounds import check_counts


def _caller(exc: BaseException) -> str:
    """``file:line`` of the innermost frame of ``exc``'s traceback: the code that called
    ``sys.exit`` (or raised SystemExit)."""
    frames = traceback.extract_tb(exc.__traceback__)
    return f"{frames[-1].filename}:{frames[-1].lineno}" if frames else "unknown code"


#: The positional arguments, named without dashes in refusals.
_POSITIONAL = {("export", "scene"), ("bench", "what"), ("train", "method")}


def check_empty(args: argparse.Namespace) -> None:
    """A DbenchInputError naming the first option given an empty value (``--method ''``,
    ``--out ''``, ``--spp ,``): no option takes one, and reading it as "not given" would run
    the default (the noisy input alone, every scene, the working directory) in its place."""
    for dest, value in vars(args).items():
        # a repeatable option is a list: the empty one of its values is named
        empty = [v for v in (value if isinstance(value, list) else [value])
                 if isinstance(v, str) and not v.replace(",", "").strip()]
        if empty:
            name = dest if (args.command, dest) in _POSITIONAL else f"--{dest.replace('_', '-')}"
            raise DbenchInputError(f"{name}: empty ({empty[0]!r}); give a value "
                                   f"(dbench {args.command} --help lists the choices)")


def check_exclusive(args: argparse.Namespace) -> None:
    """``--cache DIR`` with ``--no-cache`` is refused: the second would leave the first
    unread without a word."""
    if getattr(args, "no_cache", False) and getattr(args, "cache", None) is not None:
        raise DbenchInputError(f"--cache {args.cache}: --no-cache renders everything afresh "
                               f"and reads no cache; give one of them")


def check_args(args: argparse.Namespace) -> None:
    """The checks of the module docstring that every command makes on its parsed arguments
    before it does anything (a DbenchInputError naming the first one that fails)."""
    check_empty(args)
    check_counts(args)
    check_exclusive(args)


def command(func: Callable[[argparse.Namespace], int]) -> Callable[[argparse.Namespace], int]:
    """``func`` (a command) with the module docstring's checks."""
    @functools.wraps(func)
    def run(args: argparse.Namespace) -> int:
        check_args(args)
        try:
            return func(args)
        except SystemExit as exc:
            from ..datasets.scenes.build import exit_message

            raise DbenchInputError(
                f"{_caller(exc)} called {exit_message(exc)} during dbench {args.command}; "
                f"plugins and scene files cannot end dbench (their errors are reported)"
            ) from None
    return run


__all__ = ["command", "check_args", "check_empty", "check_exclusive"]
