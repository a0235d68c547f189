"""The study scripts (``python -m dbench.studies.<name>``) parse their options with dbench's own
:class:`dbench.options.Parser`, as ``dbench`` does (README.md, "Usage"): a single-valued option
given twice is refused in one line, exit 2, where argparse's own parser kept the last value
without a word (``--res 64 --res 16`` ran the study at 16). Each script's parser is built by
its ``build_parser()``, without running the study; the options are read off the parser, so an
option added later is covered."""
from __future__ import annotations

import argparse
import importlib
import pkgutil

import pytest

import dbench.studies
from dbench.options import Parser

STUDIES = sorted(m.name for m in pkgutil.iter_modules(dbench.studies.__path__))
#: The actions meant to take an option more than once (or none: --help).
REPEATING = (argparse._AppendAction, argparse._AppendConstAction, argparse._CountAction,
             argparse._ExtendAction, argparse._HelpAction, argparse._VersionAction)


def _parser(name: str) -> argparse.ArgumentParser:
    return importlib.import_module(f"dbench.studies.{name}").build_parser()


def _positionals(parser: argparse.ArgumentParser) -> list[str]:
    """A valid value for each positional (its first choice), so that only the option tested
    can be refused."""
    return [str(next(iter(a.choices))) if a.choices else "x"
            for a in parser._actions if not a.option_strings]


def _rows(single: bool):
    rows = []
    for name in STUDIES:
        for action in _parser(name)._actions:
            if not action.option_strings or isinstance(action, REPEATING):
                continue
            if (action.nargs != 0) == single:
                rows.append(pytest.param(name, action, id=f"{name} {action.option_strings[0]}"))
    return rows


def test_every_study_builds_its_parser_with_dbench_s_parser():
    assert len(STUDIES) == 6
    for name in STUDIES:
        parser = _parser(name)
        assert type(parser) is Parser, name
        assert parser.prog == f"python -m dbench.studies.{name}"
    assert len(_rows(True)) >= 25 and len(_rows(False)) >= 4  # not empty by accident


@pytest.mark.parametrize("name, action", _rows(True))
def test_a_study_s_single_valued_option_given_twice_is_refused(capsys, name, action):
    option = action.option_strings[0]
    first, second = tuple(action.choices)[:2] if action.choices else ("4", "16")
    parser = _parser(name)
    with pytest.raises(SystemExit) as exc:
        parser.parse_args([*_positionals(parser), option, first, option, second])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and err.count("\n") == 1, err
    assert err == (f"dbench: {option}: given twice ({first!r}, {second!r}); python -m "
                   f"dbench.studies.{name} takes one {option}\n"), err
    args = parser.parse_args([*_positionals(parser), option, second])  # once: taken
    assert getattr(args, action.dest) == (action.type(second) if action.type else second)


@pytest.mark.parametrize("name, action", _rows(False))
def test_a_study_s_flag_given_twice_is_taken_once(name, action):
    parser = _parser(name)
    option = action.option_strings[0]
    args = parser.parse_args([*_positionals(parser), option, option])
    assert getattr(args, action.dest) == action.const
