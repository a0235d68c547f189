"""The command-line reference, docs/cli.md, written from the parsers themselves: every
command of :func:`dbench.cli.command_parser` (the parser ``main()`` reads a command line with)
and every study script's ``build_parser()``, each option with its help text, value, choices
and default. Regenerate the page after changing an option::

    python -m dbench.cli.reference > docs/cli.md

tests/cli/test_cli_reference.py fails while the page differs from :func:`markdown`. The text
depends on the parsers alone, never on the terminal (argparse's ``--help`` wraps to
``$COLUMNS``; nothing here is wrapped).
"""
from __future__ import annotations

import argparse
import importlib
import pkgutil
import re
import sys

#: The command that writes the page (its first lines and the test's message name it).
REGENERATE = "python -m dbench.cli.reference > docs/cli.md"

#: Markdown's own characters in a help text, escaped so that the page shows them as written
#: (``results/runs/<new>``, ``n*0.5+0.5``, ``~/.cache``); an underscore only where it could
#: open emphasis.
_SPECIAL = re.compile(r"[\\`*<>~]|(?<![A-Za-z0-9])_|_(?![A-Za-z0-9])")


def _text(help_text: str) -> str:
    return _SPECIAL.sub(lambda m: "\\" + m.group(0), " ".join(help_text.split()))


def _code(text: str) -> str:
    return f"`{text}`"


def _help(action: argparse.Action, prog: str) -> str:
    """The help text with argparse's ``%(...)s`` expanded, as ``--help`` shows it."""
    text = action.help or ""
    if "%" in text:
        params = {k: v for k, v in vars(action).items() if v is not argparse.SUPPRESS}
        params["prog"] = prog
        if params.get("choices") is not None:
            params["choices"] = ", ".join(map(str, params["choices"]))
        text = text % params
    return text


def _value(action: argparse.Action) -> str:
    """The value an option takes as ``--help`` writes it (its metavar, ``{a,b}`` for choices,
    else its name in capitals); '' for a flag."""
    default = action.dest.upper() if action.option_strings else action.dest
    return argparse.HelpFormatter("")._format_args(action, default) if action.nargs != 0 else ""


def _facts(action: argparse.Action) -> list[str]:
    """What the parser itself says about an option: required, repeatable, choices (where a
    metavar hides them), default (the parser's: None, where the help text says what stands in
    for it, is not shown)."""
    facts = []
    if action.required and action.option_strings:
        facts.append("required")
    if isinstance(action, (argparse._AppendAction, argparse._ExtendAction)):
        facts.append("repeatable")
    if action.choices is not None and action.metavar is not None:  # else the value shows them
        facts.append("one of " + ", ".join(_code(str(c)) for c in action.choices))
    if action.option_strings and action.nargs != 0 and action.default not in (
            None, argparse.SUPPRESS):
        facts.append(f"default {_code(str(action.default))}")
    return facts


def _shown(parser: argparse.ArgumentParser) -> list[argparse.Action]:
    return [a for a in parser._actions if a.help is not argparse.SUPPRESS
            and not isinstance(a, (argparse._HelpAction, argparse._SubParsersAction))]


def _synopsis(prog: str, parser: argparse.ArgumentParser) -> str:
    """``prog``, its positionals and required options, then ``[options]``."""
    words = [prog]
    for a in _shown(parser):
        if not a.option_strings:
            words.append(_value(a) if a.choices else a.dest.upper())
        elif a.required:
            words.append(f"{a.option_strings[0]} {_value(a)}".strip())
    if any(a.option_strings and not a.required for a in _shown(parser)):
        words.append("[options]")
    return " ".join(words)


def _options(prog: str, parser: argparse.ArgumentParser) -> list[str]:
    lines = []
    for a in _shown(parser):
        if a.option_strings:
            name = ", ".join(a.option_strings)
            name += f" {_value(a)}" if _value(a) else ""
        else:
            name = _value(a) if a.choices else a.dest.upper()
        facts, about = _facts(a), _text(_help(a, prog))
        lines.append(f"- {_code(name)}" + (f" ({'; '.join(facts)})" if facts else "")
                     + (f": {about}" if about else ""))
    return lines


def _section(title: str, about: str | None, prog: str, parser: argparse.ArgumentParser,
             synopsis: str | None = None) -> list[str]:
    """A command's section; ``about`` is Markdown already."""
    lines = [f"## {title}", ""]
    if about:
        lines += [about, ""]
    lines += ["```bash", synopsis or _synopsis(prog, parser), "```", ""]
    return lines + _options(prog, parser) + [""]


def _commands(parser: argparse.ArgumentParser) -> list[tuple[str, str, argparse.ArgumentParser]]:
    """(name, one-line help, parser) of each command, in the parser's order."""
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    about = {c.dest: c.help for c in sub._choices_actions}
    return [(name, about.get(name) or "", p) for name, p in sub.choices.items()]


def _studies() -> list[tuple[str, argparse.ArgumentParser]]:
    import dbench.studies

    names = sorted(m.name for m in pkgutil.iter_modules(dbench.studies.__path__))
    return [(n, importlib.import_module(f"dbench.studies.{n}").build_parser()) for n in names]


def markdown() -> str:
    """docs/cli.md: every dbench command's options, then every study script's."""
    from . import command_parser

    parser = command_parser()
    commands = _commands(parser)
    studies = _studies()
    lines = [
        "# Command-line reference",
        "",
        "Generated from dbench's own parsers by `dbench/cli/reference.py`: do not edit it by "
        "hand. After adding or changing an option (its `help=` text is what shows here), "
        "regenerate it:",
        "",
        "```bash",
        REGENERATE,
        "```",
        "",
        "`tests/cli/test_cli_reference.py` fails while this page is out of date. README.md, "
        "\"Usage\", shows the commands at work; `dbench COMMAND --help` prints the same texts.",
        "",
        "Commands: " + " · ".join(f"[{n}](#dbench-{n})" for n, _, _ in commands)
        + "; [options before the command](#dbench); [study scripts](#study-scripts).",
        "",
    ]
    for name, about, sub in commands:
        lines += _section(f"dbench {name}", _text(about), f"dbench {name}", sub)
    lines += _section("dbench", "Options that stand before the command (`--debug` and "
                      "`--plugin` may also stand after it).", "dbench", parser,
                      synopsis="dbench [--debug] [--plugin MODULE_OR_FILE.py] COMMAND ...")
    lines += ["## Study scripts", "",
              "The studies behind the published results, each run as `python -m "
              "dbench.studies.<name>` and parsed as dbench's commands are.", ""]
    for name, study in studies:
        prog = f"python -m dbench.studies.{name}"
        lines += ["#" + line if line.startswith("## ") else line
                  for line in _section(prog, _text(study.description or ""), prog, study)]
    return "\n".join(lines).rstrip("\n") + "\n"


def main() -> int:
    """Write :func:`markdown` to standard output, UTF-8 whatever the locale."""
    sys.stdout.buffer.write(markdown().encode("utf-8"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
