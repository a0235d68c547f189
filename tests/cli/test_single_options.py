"""A single-valued option given twice is refused in one line, exit 2, before the command does
anything (dbench.options.Once; README.md, "Usage"): ``run --res 8 --res 16`` rendered at 16,
``--out a --out b`` wrote b, ``--device cpu --device cuda`` ran on cuda, each without a word.
A flag given twice asks for the same thing again and is let through; a list option (and
``--param``, ``--scene-param``, ``--plugin``) still adds each occurrence.

The options are read off the parser itself, so an option added later is covered here."""
from __future__ import annotations

import argparse

import pytest

from dbench import cli
from dbench.cli.parser import build_parser
from dbench.options import Parser

#: What each command needs besides the option tested (its positionals, its required options).
REQUIRED = {"run": ["--method", "noisy", "--scene", "cornell"], "export": ["cornell", "--out", "o"],
            "bench": ["jbf"], "train": ["nca"]}
#: The actions meant to take an option more than once (or none: --help).
REPEATING = (argparse._AppendAction, argparse._AppendConstAction, argparse._CountAction,
             argparse._ExtendAction, argparse._HelpAction, argparse._VersionAction)


def _options(single: bool):
    """(command, option, action) of every subcommand's option: the single-valued ones (values,
    not flags) or the repeatable ones (``append``)."""
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    found = []
    for name, parser in sub.choices.items():
        for action in parser._actions:
            if not action.option_strings:
                continue
            if single and not isinstance(action, REPEATING) and action.nargs != 0:
                found.append((name, action.option_strings[0], action))
            elif not single and isinstance(action, argparse._AppendAction):
                found.append((name, action.option_strings[0], action))
    return found


def _params(rows):
    return [pytest.param(*row, id=f"{row[0]} {row[1]}") for row in rows]


def _flags():
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return [(name, action.option_strings[0], action.dest) for name, parser in sub.choices.items()
            for action in parser._actions
            if action.option_strings and action.nargs == 0
            and not isinstance(action, REPEATING)]


def _argv(command: str, option: str, *values: str) -> list[str]:
    """``command`` with its required arguments (the option tested left out of them) and
    ``option`` given once for each of ``values``."""
    base = list(REQUIRED.get(command, []))
    if option in base:
        i = base.index(option)
        del base[i:i + 2]
    return [command, *base, *[x for v in values for x in (option, v)]]


def _two_values(action: argparse.Action) -> tuple[str, str]:
    return tuple(action.choices)[:2] if action.choices else ("4", "16")


def test_the_commands_options_are_all_read():
    """Every command has value options, the flags and the list options are found: the
    parametrizations below are not empty by accident."""
    singles = {(c, o) for c, o, _ in _options(True)}
    assert {("run", "--res"), ("run", "--scene"), ("sweep", "--out"), ("bench", "--device"),
            ("train", "--seed"), ("report", "--results"), ("export", "--out")} <= singles
    assert {c for c, _ in singles} >= {"run", "sweep", "render", "export", "stress", "report",
                                       "bench", "train"}
    assert ("run", "--quiet", "quiet") in _flags()
    assert {("run", "--method"), ("sweep", "--scenes"), ("run", "--param")} <= {
        (c, o) for c, o, _ in _options(False)}


@pytest.mark.parametrize("command, option, action", _params(_options(True)))
def test_a_single_valued_option_given_twice_is_refused(tmp_path, monkeypatch, capsys, command,
                                                       option, action):
    from dbench.cli import parser

    def ran(func):
        def stand_in(args):
            raise AssertionError(f"dbench {command} ran with {option} given twice")
        return stand_in
    monkeypatch.setattr(parser, "command", ran)  # no command does its work here, even unrefused
    monkeypatch.chdir(tmp_path)  # relative --out, --cache, ... would land here
    first, second = _two_values(action)
    with pytest.raises(SystemExit) as exc:
        cli.main(_argv(command, option, first, second))
    out, err = capsys.readouterr()
    assert exc.value.code == 2 and out == "" and err.count("\n") == 1, err
    assert err.startswith(f"dbench: {option}: given twice (") and first in err and second in err
    assert err.endswith(f"; dbench {command} takes one {option}\n"), err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("command, option, action", _params(_options(True)))
def test_a_single_valued_option_given_once_is_taken(command, option, action):
    """The refusal above is the second occurrence, not the option: given once it parses."""
    value = _two_values(action)[1]
    args = build_parser().parse_args(_argv(command, option, value))
    expected = action.type(value) if action.type else value
    assert getattr(args, action.dest) == expected
    assert not any(k.startswith("_") for k in vars(args))  # no bookkeeping left behind


@pytest.mark.parametrize("command, option, dest", _params(_flags()))
def test_a_flag_given_twice_is_taken_once(command, option, dest):
    """A flag carries no value: its second occurrence cannot ask for anything the first did
    not, so nothing is dropped and it is let through (README.md, "Usage")."""
    once = build_parser().parse_args(_argv(command, option) + [option])
    twice = build_parser().parse_args(_argv(command, option) + [option, option])
    assert getattr(once, dest) == getattr(twice, dest) != build_parser().parse_args(
        _argv(command, option)).__dict__[dest]


@pytest.mark.parametrize("command, option, action", _params(_options(False)))
def test_a_list_option_given_twice_adds_both(command, option, action):
    args = build_parser().parse_args(_argv(command, option, "a=1", "b=2"))
    assert getattr(args, action.dest)[-2:] == ["a=1", "b=2"]


def test_two_options_writing_one_value_are_refused_together(capsys):
    """Two spellings of one setting (none in dbench today) cannot settle it by their order."""
    p = Parser(prog="dbench x")
    p.add_argument("--color", dest="color", action="store_const", const="yes")
    p.add_argument("--no-color", dest="color", action="store_const", const="no")
    assert p.parse_args(["--color", "--color"]).color == "yes"
    with pytest.raises(SystemExit) as exc:
        p.parse_args(["--color", "--no-color"])
    assert exc.value.code == 2
    assert capsys.readouterr().err == ("dbench: --color and --no-color: both given; dbench x "
                                       "takes one of them\n")


@pytest.mark.parametrize("argv", [["--debug", "--debug", "list"], ["list", "--debug", "--debug"],
                                  ["--deb", "list"], ["--deb", "--debug", "list"]])
def test_debug_is_a_flag_like_the_others(monkeypatch, capsys, argv):
    """``--debug`` is taken out of argv wherever it stands (dbench.cli.main), not by the
    subcommand's parser: given twice it is let through as every flag is, and abbreviated before
    the command (``--deb``, which argparse takes for it) it shows the traceback: it was
    accepted and then ignored."""
    from dbench.cli import parser

    def failing(func):
        def stand_in(args):
            raise RuntimeError("an internal error")
        return stand_in
    monkeypatch.setattr(parser, "command", failing)
    with pytest.raises(RuntimeError, match="an internal error"):  # --debug: the traceback
        cli.main(argv)
    assert cli.main([a for a in argv if not a.startswith("--deb")]) == 1  # one line without
    assert "internal error" in capsys.readouterr().err
