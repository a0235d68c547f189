"""The command lines and options the documentation shows are ones dbench has and takes.

Where they are read: README.md, CONTRIBUTING.md and every page under docs/: each line of a fenced
code block (continuation backslashes joined; a comment line ``# my.py: dbench run ...`` holds a
command too, from ``dbench``), and each inline code span that starts with a command.

Whose a command is, by its first word after any ``NAME=value`` environment prefixes: ``dbench``
or ``python -m dbench`` is dbench's; ``python -m dbench.studies.<name>`` (or
``dbench.studies.<name>``) is that study script's, read with its ``build_parser()``; a span that
starts with a subcommand name and holds an option (``run --res 8 --res 16``), or an option
after a subcommand's possessive (`` `export`'s `--out` ``), is dbench's, that subcommand's.
Anything else (``pytest -m slow``, ``pip install``, ``bash scripts/...``, another project's
tool) is that program's and not read here. Shell syntax: ``# ...`` comments dropped, a pipe,
``;`` or ``&&`` ends the command, a redirection is dropped.

How a command is checked:

* Its names, always: the subcommand exists, and every option (``--name``, ``--name=value``)
  is one of that subcommand's or of those before it (``--debug``, ``--plugin``), exactly as
  written (no abbreviation); for ``bench WHAT``, one that benchmark reads
  (dbench.cli.bench.READS).
* Its values too, by parsing it as ``dbench`` does (dbench.cli.command_parser; ``--debug`` and
  ``--plugin FILE`` taken out as main() takes them, so no plugin is imported and nothing runs)
  and checking it as every command does first (dbench.cli.guard.check_args: empty values,
  counts; ``bench`` also its option check, dbench.cli.bench.check_bench_options), unless it is a
  template or a reference. A template holds a placeholder: ``...`` or ``…``, ``<name>``, an
  upper-case word (``NAME``, ``DIR``, ``N``, ``KEY=VALUE``), alternatives ``a|b``, an optional
  part ``[--arch 90]`` or a ``$variable``. A reference names a command or option without values:
  nothing but option names after the subcommand (``dbench run``, ``dbench run --ref-spp``).
  Options after a subcommand in prose (above) often show a refusal (``bench jbf --bins 3``):
  their names alone are checked.

Every other long option written in the documentation (``--res`` in prose, a table) is an option
of some dbench command, unless it is one of :data:`NOT_DBENCH`, each another program's (on
docs/cli.md, written from the parsers, also a study script's: its last section lists them).
"""
from __future__ import annotations

import argparse
import contextlib
import functools
import importlib
import io
import pkgutil
import re
import shlex
from dataclasses import dataclass
from pathlib import Path

import pytest

import dbench.studies
from dbench.cli import command_parser, split_plugin_args
from dbench.cli.bench import READS, check_bench_options
from dbench.cli.guard import check_args
from dbench.errors import DbenchInputError, UnknownNameError

ROOT = Path(__file__).resolve().parent.parent

#: Long options the documentation names that are not dbench's, each with whose it is.
NOT_DBENCH = {
    "--clean_aux": "OIDN's training script (docs/formats.md, OIDN's layout)",
    "--warmup": "StatMC's timing harness (docs/metrics.md)",
    "--keep-integrator": "an option dbench says it does not have (docs/formats.md)",
}

#: a fenced code block, also indented in a list item
FENCE = re.compile(r"^[ \t]*```[^\n]*\n(.*?)^[ \t]*```", re.M | re.S)
#: an inline code span, across line breaks but not across a blank line
SPAN = re.compile(r"(?<!`)`([^`\n]+(?:\n[^`\n]+)*?)`(?!`)")
#: a subcommand's option in prose: `` `export`'s `--frames` ``
POSSESSIVE = re.compile(r"`(?:dbench )?([a-z-]+)`'s\s+`(--[^`]+)`")
ENV = re.compile(r"[A-Za-z_][A-Za-z0-9_]*=")
PLACEHOLDER = re.compile(r"\.\.\.|…|<[^>]*>|\||\[|\]|\$|(?:^|[=:,])[A-Z][A-Z0-9_]*(?![a-z])")
LONG = re.compile(r"(?<![\w-])--[A-Za-z][\w-]*")
STUDIES = sorted(m.name for m in pkgutil.iter_modules(dbench.studies.__path__))


@dataclass(frozen=True)
class Command:
    where: str  # file:line
    program: str  # "dbench" or the study's module name
    argv: tuple[str, ...]
    text: str
    mention: bool = False  # options after a subcommand in prose, maybe a refusal shown

    @property
    def template(self) -> bool:
        return self.mention or any(PLACEHOLDER.search(a) for a in self.argv)


def _docs() -> list[Path]:
    return [ROOT / "README.md", ROOT / "CONTRIBUTING.md",
            *sorted(ROOT.joinpath("docs").rglob("*.md"))]


def _line(text: str, at: int) -> int:
    return text.count("\n", 0, at) + 1


#: lines that start like a command and that the shell cannot read (an unbalanced quote)
UNREADABLE: list[str] = []


def _tokens(text: str) -> list[str] | None:
    """The words of one shell command (None: not one, e.g. an unbalanced quote)."""
    try:
        words = shlex.split(text, comments=True)
    except ValueError as exc:
        if re.match(r"(?:\S+=\S* )*(?:python3? -m )?dbench\b", text):
            UNREADABLE.append(f"`{text}`: {exc}")
        return None
    out: list[str] = []
    skip = False
    for w in words:
        if skip:
            skip = False
            continue
        if w in ("|", "||", "&&", ";", "&"):
            break
        if re.fullmatch(r"\d?[<>]{1,2}&?", w):  # a redirection and its target
            skip = True
            continue
        out.append(w)
    while out and ENV.match(out[0]):
        out.pop(0)
    return out


@functools.cache
def _subcommands() -> dict[str, argparse.ArgumentParser]:
    sub = next(a for a in command_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def _command(words: list[str], where: str, text: str, in_span: bool) -> Command | None:
    """The dbench or study command ``words`` is, else None (another program's)."""
    if words[:1] == ["dbench"]:
        return Command(where, "dbench", tuple(words[1:]), text)
    if len(words) >= 3 and re.fullmatch(r"python3?", words[0]) and words[1] == "-m":
        if words[2] == "dbench":
            return Command(where, "dbench", tuple(words[3:]), text)
        words = words[2:]
    study = re.fullmatch(r"dbench\.studies\.(\w+)", words[0]) if words else None
    if study:
        return Command(where, study.group(1), tuple(words[1:]), text)
    if in_span and words and words[0] in _subcommands() and any(
            w.startswith("--") for w in words[1:]):
        return Command(where, "dbench", tuple(words), text, mention=True)
    return None


def _commands(docs: list[Path] | None = None) -> list[Command]:
    found = []
    for doc in _docs() if docs is None else docs:
        text = doc.read_text(encoding="utf-8")
        name = doc.relative_to(ROOT) if doc.is_relative_to(ROOT) else doc.name
        for block in FENCE.finditer(text):
            body = block.group(1)
            lines = body.split("\n")
            at = _line(text, block.start(1))
            i = 0
            while i < len(lines):
                first, line = i, lines[i]
                while line.endswith("\\") and i + 1 < len(lines):
                    i += 1
                    line = line[:-1] + " " + lines[i]
                i += 1
                stripped = line.strip()
                if stripped.startswith("#"):  # a command quoted in a comment, from "dbench"
                    quoted = re.search(r"(?<![\w./-])dbench (?=-|[a-z])", stripped)
                    if not quoted:
                        continue
                    stripped = stripped[quoted.start():]
                words = _tokens(stripped)
                if words:
                    cmd = _command(words, f"{name}:{at + first}", stripped, in_span=False)
                    if cmd:
                        found.append(cmd)
        prose = FENCE.sub(lambda m: "\n" * m.group(0).count("\n"), text)
        for span in SPAN.finditer(prose):
            code = " ".join(span.group(1).split())
            words = _tokens(code)
            if words:
                cmd = _command(words, f"{name}:{_line(prose, span.start())}", code, in_span=True)
                if cmd:
                    found.append(cmd)
        for m in POSSESSIVE.finditer(prose):
            words = _tokens(" ".join(m.group(2).split()))
            if m.group(1) in _subcommands() and words:
                found.append(Command(f"{name}:{_line(prose, m.start())}", "dbench",
                                     (m.group(1), *words), " ".join(m.group(0).split()),
                                     mention=True))
    return found


def _options(parser: argparse.ArgumentParser) -> set[str]:
    return {o for a in parser._actions for o in a.option_strings}


#: options that stand before the command as well as after it (main takes them out)
TOP = {"--debug", "--plugin", "-h", "--help"}


def _name_errors(cmd: Command) -> list[str]:
    """What in ``cmd``'s names dbench (or the study) does not have."""
    words = list(cmd.argv)
    if cmd.program != "dbench":
        if cmd.program not in STUDIES:
            return [f"no study script dbench.studies.{cmd.program}"]
        known = _options(importlib.import_module(f"dbench.studies.{cmd.program}").build_parser())
        return [f"{o}: not an option of python -m dbench.studies.{cmd.program}"
                for o in _option_names(words) if o not in known]
    commands = _subcommands()
    i = 0
    while i < len(words) and words[i].startswith("-"):  # options before the command
        i += 2 if words[i] == "--plugin" else 1
    name = words[i] if i < len(words) else None
    errors = [f"{o}: not an option before the command (dbench takes {sorted(TOP)})"
              for o in _option_names(words[:i]) if o not in TOP]
    if name is None or PLACEHOLDER.search(name):  # "dbench --debug ...": any command
        known = set().union(*(_options(p) for p in commands.values()), TOP)
        return errors + [f"{o}: no dbench command has it" for o in _option_names(words[i:])
                         if o not in known]
    if name not in commands:
        return errors + [f"{name!r}: not a dbench command ({', '.join(commands)})"]
    rest = words[i + 1:]
    known = _options(commands[name]) | TOP
    errors += [f"{o}: not an option of dbench {name}" for o in _option_names(rest)
               if o not in known]
    what = rest[0] if name == "bench" and rest and not rest[0].startswith("-") else None
    if what and not PLACEHOLDER.search(what) and not cmd.mention:
        reads = {f"--{d}" for d in READS.get(what, READS["method"]) + ("out",)} | TOP
        errors += [f"{o}: dbench bench {what} does not read it" for o in _option_names(rest)
                   if o in known and o not in reads]
    return errors


def _option_names(words) -> list[str]:
    names = []
    for w in words:
        w = w.lstrip("[")
        if w.startswith("-") and w not in ("-", "--") and not re.fullmatch(r"-[\d.]+", w):
            names.append(w.split("=", 1)[0].rstrip("]"))
    return names


def _reference(cmd: Command) -> bool:
    """Nothing but option names after the subcommand, if any: ``dbench``, ``dbench run``,
    ``dbench run --ref-spp``."""
    words = [w for w in cmd.argv if w != "--debug"]
    return all(w.startswith("--") for w in words[1:])


def _parse_error(cmd: Command) -> str | None:
    """Why dbench (or the study script) would refuse ``cmd`` while parsing it (None: it takes
    it), as main() parses: no plugin imported, nothing run."""
    err = io.StringIO()
    try:
        if cmd.program != "dbench":
            study = importlib.import_module(f"dbench.studies.{cmd.program}")
            with contextlib.redirect_stderr(err):
                study.build_parser().parse_args(list(cmd.argv))
            return None
        argv, _plugins = split_plugin_args([a for a in cmd.argv if a != "--debug"])
        with contextlib.redirect_stderr(err):
            args = command_parser().parse_args(argv)
        check_args(args)  # what every command checks first (empty values, counts)
        if args.command == "bench":  # the options bench refuses before it benchmarks
            check_bench_options(args)
    except SystemExit:
        return err.getvalue().strip() or "exit"
    except (DbenchInputError, UnknownNameError) as exc:
        return str(exc)
    return None


COMMANDS = _commands()


def test_the_documentation_shows_commands():
    """Not empty by accident: the Usage block alone has 30 lines, and every kind is met."""
    dbench_lines = [c for c in COMMANDS if c.program == "dbench"]
    assert len(dbench_lines) >= 100
    assert any(c.template for c in dbench_lines) and any(_reference(c) for c in dbench_lines)
    assert any(c.program in STUDIES for c in COMMANDS)
    assert sum(not c.template and not _reference(c) for c in dbench_lines) >= 40


def test_every_command_reads_as_a_shell_command():
    assert UNREADABLE == []


def test_every_command_names_a_command_and_its_options():
    wrong = [f"{c.where}: `{c.text}`: {e}" for c in COMMANDS for e in _name_errors(c)]
    assert wrong == []


def test_every_example_command_line_parses():
    """A complete example (no placeholder, not a bare reference) is one dbench takes."""
    refused = []
    for c in COMMANDS:
        if c.program in ("dbench", *STUDIES) and not c.template and not _reference(c):
            why = _parse_error(c)
            if why is not None:
                refused.append(f"{c.where}: `{c.text}`: {why}")
    assert refused == []


def test_every_long_option_in_the_documentation_is_dbench_s():
    """A long option outside a command line of another program is one of some dbench command's
    (or a study script's, in its command), or named in NOT_DBENCH with whose it is."""
    commands = _subcommands()
    known = set().union(*(_options(p) for p in commands.values()), TOP)
    # docs/cli.md's last section lists every study script's options: the page is written from
    # the parsers (tests/cli/test_cli_reference.py)
    studies = set().union(*(_options(importlib.import_module(f"dbench.studies.{s}")
                                     .build_parser()) for s in STUDIES))
    others = {c.text for c in COMMANDS if c.program != "dbench"}
    unknown = []
    for doc in _docs():
        text = doc.read_text(encoding="utf-8")
        here = known | studies if doc == ROOT / "docs" / "cli.md" else known
        for other in sorted(others, key=len, reverse=True):  # checked with their command
            written = r"\s+".join(map(re.escape, other.split()))  # across line breaks too
            text = re.sub(written, lambda m: "\n" * m.group(0).count("\n"), text)
        for m in LONG.finditer(text):
            if m.group(0) not in here and m.group(0) not in NOT_DBENCH:
                unknown.append(f"{doc.relative_to(ROOT)}:{_line(text, m.start())}: {m.group(0)}")
    assert unknown == []


BLOCK = "```bash\n{}\n```\n"


@pytest.mark.parametrize("doc, ok", [
    (BLOCK.format("dbench run --method noisy --scene cornell"), True),
    (BLOCK.format("DBENCH_CACHE=/tmp/c dbench run --method noisy \\\n  --scene cornell  # a, b"),
     True),
    (BLOCK.format("dbench run --method noisy --scene cornell --no-such-option"), False),
    (BLOCK.format("dbench run --method noisy --scene cornell --spp 0"), False),
    (BLOCK.format("dbench run --method noisy --scene cornell --out ''"), False),
    (BLOCK.format("dbench bench jbf --bins 3"), False),
    (BLOCK.format("dbench sweep ... --no-such-option"), False),
    (BLOCK.format("dbench run --method NAME --scene <scene> --spp N"), True),
    (BLOCK.format("dbench no-such-command"), False),
    (BLOCK.format("dbench bench kernels [--arch 90] [--bins N]"), False),
    (BLOCK.format("# my.py: dbench run --method blur3 --scene cornell --sp 16"), False),
    ("Run `dbench run --method noisy --scene cornell`.\n", True),
    ("Run `dbench run --method noisy\n--scene cornell --seeds`.\n", False),
    ("The `dbench run --no-such-option` option.\n", False),
    ("Its own refusal: `bench jbf --bins 3`; not an option: `run --frame`.\n", False),
    ("`export`'s `--scene`\n", False),
    ("`python -m dbench.studies.temporal_dev --seeds 0,1`\n", True),
    ("`python -m dbench.studies.temporal_dev --res 64`\n", False),
])
def test_the_check_finds_a_broken_line(tmp_path, doc, ok):
    """A broken command line is found, in a block, a comment or a span; a good one (continued,
    commented, with an environment prefix or placeholders) is taken."""
    page = tmp_path / "page.md"
    page.write_text(doc, encoding="utf-8")
    cmds = _commands([page])
    assert cmds
    bad = [e for c in cmds for e in _name_errors(c)] + [
        e for c in cmds if not c.template and not _reference(c) for e in [_parse_error(c)] if e]
    assert (not bad) == ok, bad


def test_a_plugin_in_a_command_line_is_not_imported(tmp_path):
    plugin = tmp_path / "boom.py"
    plugin.write_text("raise RuntimeError('imported')\n", encoding="utf-8")
    page = tmp_path / "page.md"
    page.write_text(BLOCK.format(f"dbench --plugin {plugin} run --method blur3 --scene cornell "
                                 f"--plugin={plugin} --debug"), encoding="utf-8")
    [cmd] = _commands([page])
    assert _name_errors(cmd) == [] and _parse_error(cmd) is None
