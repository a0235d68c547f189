"""Every option of every command and study script says what it does (``--help`` and
docs/cli.md show these texts), and the defaults a help text names are the ones the command
uses."""
from __future__ import annotations

import argparse
import importlib
import pkgutil
import re

import dbench.studies
from dbench import cli


def _parsers() -> dict[str, argparse.ArgumentParser]:
    parser = cli.command_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    studies = sorted(m.name for m in pkgutil.iter_modules(dbench.studies.__path__))
    return {"dbench": parser, **{f"dbench {n}": p for n, p in sub.choices.items()},
            **{n: importlib.import_module(f"dbench.studies.{n}").build_parser()
               for n in studies}}


def _help(command: str, option: str) -> str:
    parser = _parsers()[command]
    return next(a.help for a in parser._actions if option in a.option_strings or a.dest == option)


def test_every_option_and_argument_has_a_help_text():
    silent = [f"{name} {a.option_strings[0] if a.option_strings else a.dest}"
              for name, parser in _parsers().items() for a in parser._actions
              if not (a.help or "").strip() and not isinstance(a, argparse._SubParsersAction)]
    assert silent == []


def test_train_s_help_names_the_training_configs_defaults():
    """``--steps`` and ``--width-scale`` are overrides of the training configurations
    (dbench/learn/configs.py); their help says what is trained without them."""
    from dbench.learn.configs import AEConfig, NCAConfig

    steps = _help("dbench train", "--steps")
    assert f"nca {NCAConfig.steps}" in steps and f"autoencoder {AEConfig.steps}" in steps
    assert f"(default {AEConfig.width_scale})" in _help("dbench train", "--width-scale")


def test_train_s_reference_spp_is_the_one_its_help_names(monkeypatch, tmp_path):
    """train renders its training references at its own spp, whatever $DBENCH_REF_SPP says
    (the other commands' --ref-spp default)."""
    from dbench.learn import train

    given = {}

    def stand_in(method, **kwargs):
        given.update(kwargs)
        return None, ()

    monkeypatch.setattr(train, "run_training", stand_in)
    monkeypatch.setenv("DBENCH_REF_SPP", "64")
    rc = cli.main(["train", "nca", "--out", str(tmp_path / "model"),
                   "--cache", str(tmp_path / "cache")])
    assert rc == 0
    help_text = _help("dbench train", "--ref-spp")
    assert re.search(rf"\(default {given['ref_spp']}\b", help_text), help_text
    assert "$DBENCH_REF_SPP does not apply" in help_text

