"""docs/cli.md, the command-line reference, is what dbench.cli.reference writes from the parsers
now: an option added or changed without regenerating the page fails here, naming the command
that regenerates it. The page names every option of every command and study script, and it
does not depend on the terminal it is written from."""
from __future__ import annotations

import argparse
import difflib
import os
import subprocess
import sys
from pathlib import Path

from dbench.cli import command_parser, reference

ROOT = Path(__file__).resolve().parent.parent.parent
PAGE = ROOT / "docs" / "cli.md"


def test_docs_cli_md_is_the_generated_reference():
    want = reference.markdown()
    have = PAGE.read_text(encoding="utf-8") if PAGE.is_file() else ""
    diff = "".join(list(difflib.unified_diff(have.splitlines(True), want.splitlines(True),
                                             "docs/cli.md", "generated"))[:40])
    assert have == want, (f"docs/cli.md is out of date; regenerate it: "
                          f"{reference.REGENERATE}\n{diff}")


def _parsers():
    parser = command_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    yield "dbench", parser
    for name, p in sub.choices.items():
        yield f"dbench {name}", p
    for name, p in reference._studies():
        yield f"python -m dbench.studies.{name}", p


def _section(text: str, title: str) -> str:
    heading = next(h for h in (f"## {title}\n", f"### {title}\n") if h in text)
    body = text.split(heading, 1)[1]
    return body.split("\n## ", 1)[0].split("\n### ", 1)[0]


def test_the_page_has_a_section_naming_every_option():
    text = reference.markdown()
    missing = []
    for title, parser in _parsers():
        body = _section(text, title)
        for a in parser._actions:
            if isinstance(a, (argparse._HelpAction, argparse._SubParsersAction)):
                continue
            name = a.option_strings[0] if a.option_strings else reference._value(a)
            if f"- `{name}" not in body and f"- `{a.dest.upper()}`" not in body:
                missing.append(f"{title} {name}")
    assert missing == []
    # the options that were documented nowhere else, each in its command's section
    for title, option in [("dbench list", "--methods-only"), ("dbench report", "--results"),
                          ("dbench report", "--sweep"), ("dbench export", "--name"),
                          ("dbench bench", "--width"), ("dbench train", "--from-weights")]:
        assert f"- `{option}" in _section(text, title), (title, option)


def test_the_page_shows_defaults_choices_and_markdown_s_characters_as_written():
    text = reference.markdown()
    assert "- `--executor {local,ray}` (default `local`): " in text
    assert "- `--method METHOD` (required; repeatable): " in text
    assert "- `--seeds SEEDS` (default `1`): " in text and "95 % Student-t" in text  # %% expanded
    assert "results/runs/\\<new\\>" in text and "n\\*0.5+0.5" in text
    assert "normal_encoding" in text  # an underscore inside a word is not escaped


def test_the_regenerating_command_writes_the_page_whatever_the_terminal():
    """The command the page and the failure name writes it; argparse wraps ``--help`` to
    $COLUMNS, the page written under a narrow terminal (and a C locale) is the same."""
    assert reference.REGENERATE.startswith("python -m dbench.cli.reference > ")
    env = {**os.environ, "COLUMNS": "20", "LINES": "5", "LC_ALL": "C", "PYTHONIOENCODING": ""}
    out = subprocess.run([sys.executable, "-m", "dbench.cli.reference"], capture_output=True,
                         env=env, cwd=ROOT, check=True).stdout.decode("utf-8")
    assert out == reference.markdown()

