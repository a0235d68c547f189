"""argparse's refusals are one line, ``dbench: <argparse's message>``, exit 2, without its usage
block, from the main parser and every subcommand's (dbench/cli/parser.py ``Parser``); ``--help``
still prints the help, exit 0 (README.md, "Usage")."""
from __future__ import annotations

import subprocess
import sys

import pytest

from dbench import cli


def _exit(argv) -> int:
    try:
        return cli.main(list(argv))
    except SystemExit as exc:  # argparse ends the parse with SystemExit, as always
        return exc.code


@pytest.mark.parametrize("argv, words", [
    (["sweep", "--executor", "bogus"], ["--executor", "'bogus'", "'local', 'ray'"]),
    (["train", "bogus"], ["argument method", "'nca', 'autoencoder'"]),
    (["run"], ["required", "--method", "--scene"]),
    (["run", "--method", "jbf", "--scene", "cornell", "--bogus"],
     ["unrecognized arguments: --bogus"]),
    (["bogus"], ["argument command", "'run'", "'train'"]),
    ([], ["required: command"]),
    (["bench"], ["required: what"]),
    (["export"], ["required"]),
    (["run", "--method", "jbf", "--scene", "cornell", "--spp"], ["--spp", "expected one"]),
    (["--bogus", "list"], ["unrecognized arguments: --bogus"]),
])
def test_a_parse_error_is_one_line_and_exit_2(capsys, argv, words):
    rc = _exit(argv)
    out, err = capsys.readouterr()
    assert rc == 2 and out == "", (rc, out)
    assert err.startswith("dbench: ") and err.count("\n") == 1, err
    assert "usage:" not in err and "Traceback" not in err, err
    for w in words:
        assert w in err, err


@pytest.mark.parametrize("argv", [["--help"], ["run", "--help"], ["train", "-h"],
                                  ["bench", "--help"]])
def test_help_is_printed_whole_with_exit_0(capsys, argv):
    assert _exit(argv) == 0
    out, err = capsys.readouterr()
    assert out.startswith("usage: dbench") and "options:" in out and err == ""


def test_every_subcommand_parser_refuses_in_one_line():
    """Each subcommand's parser is the one-line Parser (argparse makes subparsers of the
    parent's class only where the parent says so)."""
    from dbench.cli.parser import Parser, build_parser

    parser = build_parser()
    assert type(parser) is Parser
    subs = [a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction"]
    assert subs and all(type(p) is Parser for p in subs[0].choices.values())


def test_the_installed_command_prints_one_line():
    """The real process: stderr holds one line, the exit status is 2."""
    r = subprocess.run([sys.executable, "-m", "dbench", "train", "bogus"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr.count("\n") == 1 and r.stderr.startswith("dbench: argument method"), r.stderr
