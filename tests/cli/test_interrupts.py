"""Ctrl-C and SIGTERM end any command with 130 and "dbench: interrupted", also where a library
turned the interrupt into another error on its way (Mitsuba's variant being set gave "cannot set
Mitsuba variant", exit 3, or a NameError, exit 1) or swallowed it (a ``__del__``): the command's
signal handlers flag it (dbench/report/run_output.py interrupts_flagged; dbench/cli)."""
from __future__ import annotations

import os
import signal

import pytest

from dbench import cli
from dbench.cli import parser
from dbench.errors import RendererUnavailableError


def _interrupted_inside(convert):
    """A `list` command that receives SIGINT and lets ``convert`` handle the interrupt."""
    def cmd(args):
        try:
            os.kill(os.getpid(), signal.SIGINT)
        except KeyboardInterrupt as exc:
            return convert(exc)
        return 0
    return cmd


@pytest.mark.parametrize("convert", [
    pytest.param(lambda exc: (_ for _ in ()).throw(
        RendererUnavailableError("cannot set Mitsuba variant llvm_ad_rgb: <built-in function "
                                 "__import__> returned a result with an exception set")),
        id="renderer-unavailable"),
    pytest.param(lambda exc: (_ for _ in ()).throw(NameError("name '_drjit_ext' is not "
                                                            "defined")), id="internal-error"),
    pytest.param(lambda exc: 0, id="swallowed")])
def test_an_interrupt_is_130_whatever_it_became(monkeypatch, capsys, convert):
    monkeypatch.setattr(parser, "cmd_list", _interrupted_inside(convert))
    assert cli.main(["list"]) == 130
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["dbench: interrupted"]
    # the handlers are the process's own again afterwards, and the next command starts clean
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    monkeypatch.undo()
    assert cli.main(["list"]) == 0


def test_a_real_error_without_an_interrupt_keeps_its_code(monkeypatch, capsys):
    def cmd(args):
        raise RendererUnavailableError("no renderer")
    monkeypatch.setattr(parser, "cmd_list", cmd)
    assert cli.main(["list"]) == 3
    assert capsys.readouterr().err.strip() == "dbench: no renderer"
