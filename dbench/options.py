"""The argument parser every command line of dbench builds on: ``dbench`` and its subcommands
(dbench/cli/parser.py) and the study scripts (``python -m dbench.studies.<name>``). A refusal is
one line, exit 2, and a single-valued option given twice is refused, never settled by keeping
the last value (README.md, "Usage"). Only argparse below it, so any room may build on it."""
from __future__ import annotations

import argparse
from typing import NoReturn


class Parser(argparse.ArgumentParser):
    """An ArgumentParser whose refusals are one line, ``dbench: <argparse's message>``, exit 2
    (README.md, "Usage"), without the usage block argparse prints; ``--help`` is unchanged.
    Every subcommand's parser is one too (``parser_class``), and every single-valued option of
    each (``store`` and the flags, the default actions) is given at most once (:class:`Once`);
    ``append`` options (``--param``, the lists) repeat as before."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        for name, action in ((None, Once), ("store", Once), ("store_const", _OnceConst),
                             ("store_true", _OnceTrue), ("store_false", _OnceFalse)):
            self.register("action", name, action)

    def parse_known_args(self, args=None, namespace=None):
        namespace, rest = super().parse_known_args(args, namespace)
        vars(namespace).pop(_GIVEN, None)  # this parse's bookkeeping, not an argument
        return namespace, rest

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"dbench: {' '.join(message.split())}\n")


#: The namespace attribute where one parse keeps the options it has met: dest -> (action,
#: value). On the namespace, not the action, so that one parser parses any number of times.
_GIVEN = "_dbench_given"


class _GivenOnce(argparse.Action):
    """An option that holds one value: given a second time it is refused in one line, exit 2,
    before the command does anything, never settled by keeping the last value without a word
    (README.md, "Usage"). A flag (no value: ``--quiet``, ``--no-cache``) given twice is let
    through: it asks for the same thing again and nothing is dropped. Two options that write
    one dest are refused together whatever they are."""

    def __call__(self, parser, namespace, values, option_string=None):
        if option_string is not None:  # a positional is filled once by argparse itself
            given = vars(namespace).setdefault(_GIVEN, {})
            first = given.get(self.dest)
            value = self.const if self.nargs == 0 else values
            if first is not None and not (first[0] is self and self.nargs == 0):
                if first[0] is self:
                    parser.error(f"{option_string}: given twice ({str(first[1])!r}, "
                                 f"{str(value)!r}); {parser.prog} takes one {option_string}")
                parser.error(f"{first[0].option_strings[0]} and {option_string}: both given; "
                             f"{parser.prog} takes one of them")
            given[self.dest] = (self, value)
        super().__call__(parser, namespace, values, option_string)


class Once(_GivenOnce, argparse._StoreAction):
    """``store`` given at most once (:class:`_GivenOnce`): the action of every option that
    takes one value (``run --scene``, ``--res``, ``--out``, ``--seed``, ...)."""


class _OnceConst(_GivenOnce, argparse._StoreConstAction):
    """``store_const``, at most once (:class:`_GivenOnce`)."""


class _OnceTrue(_GivenOnce, argparse._StoreTrueAction):
    """``store_true``, at most once (:class:`_GivenOnce`)."""


class _OnceFalse(_GivenOnce, argparse._StoreFalseAction):
    """``store_false``, at most once (:class:`_GivenOnce`)."""


__all__ = ["Once", "Parser"]
