"""Command line: ``dbench run | sweep | stress | report | list | render | export | bench | train``.

Exit codes: 0 success, also when the reader of standard output goes away early
(``dbench run ... | head -1``: the files are written, the rest of the printed text is dropped);
2 unknown names or bad arguments (the valid names are listed), a plugin asked for that failed
to load (named, with the reason), a result that cannot be written (full disk, quota, read-only
or unwritable folder: one line ``dbench: cannot write <path>: <reason>``; ``run`` then leaves
no ``--out`` behind and an earlier run's folder there untouched) or a standard output that
cannot be written (``> /dev/full``: the files are written, one line on stderr);
3 renderer unavailable; 4 some methods failed: ``run`` names each on stderr and in the
report's "Failed" section and writes every other method's results, ``sweep`` names its error
cells (of this sweep's grid only) on stderr and keeps the rest, ``stress`` has failed cases,
``bench METHOD`` names the method's failure in one line and writes nothing;
130 interrupted (Ctrl-C or SIGTERM, at any point of a command, also where a library turned the
interrupt into another error or swallowed it: ``run`` removes its temporary folder, so no
partial ``--out`` is left); 1 an internal error (one line; ``--debug`` shows the traceback).
README.md, "Usage", says where ``run`` writes and how it replaces an earlier run's folder.
"""
from __future__ import annotations

import argparse
import os
import sys
from typing import Sequence

from ..errors import DbenchInputError, RendererUnavailableError, UnknownNameError
from . import streams
from .args import parse_params
from .parser import PLUGIN_HELP, build_parser

#: The commands that keep the libraries' warnings, Mitsuba's log lines included, in a log
#: beside their output (run.log, sweep.log, export.log, stress.log): under --quiet none of them
#: shows those lines on the terminal (dbench/datasets/mitsuba_log.py).
LOGGED = ("run", "sweep", "export", "stress")


def split_plugin_args(argv: Sequence[str]) -> tuple[list[str], list[str]]:
    """(argv without ``--plugin X`` / ``--plugin=X``, the plugin specs): the option is taken
    wherever it stands, before or after the subcommand."""
    rest, specs = [], []
    i = 0
    while i < len(argv):
        a = argv[i]
        if a == "--plugin":
            if i + 1 >= len(argv):
                raise DbenchInputError("--plugin: expected a module name or a .py file")
            specs.append(argv[i + 1])
            i += 2
            continue
        if a.startswith("--plugin="):
            specs.append(a.split("=", 1)[1])
        elif a == "--":
            rest += argv[i:]
            break
        else:
            rest.append(a)
        i += 1
    return rest, specs


def _load_plugins(args: argparse.Namespace, specs: Sequence[str]) -> None:
    """Entry points, $DBENCH_PLUGINS and --plugin, before the command runs. A --plugin or
    $DBENCH_PLUGINS entry that fails is an error (exit 2) except for ``list``, which shows it."""
    from .. import plugins, registry  # noqa: F401 - the built-in methods before the plugins

    plugins.load_all(specs, strict=args.command != "list")


def main(argv: Sequence[str] | None = None) -> int:
    """Run one command; its exit code (the module docstring lists them)."""
    from ..report import run_output

    with streams.guarded() as (out, _err):
        try:
            with run_output.interrupts_flagged():
                code = _main(argv)
                if code != 130 and run_output.terminated():  # swallowed on its way
                    print("dbench: interrupted", file=sys.stderr)
                    code = 130
        except KeyboardInterrupt:  # before the command's own handling (parsing, imports)
            print("dbench: interrupted", file=sys.stderr)
            code = 130
        out.flush()
    if out.lost is None or streams.reader_gone(out.lost):
        return code
    try:
        print(f"dbench: cannot write standard output: {out.lost.strerror or out.lost}",
              file=sys.stderr)
    except OSError:
        pass  # stderr is gone too: the exit code says it
    return code or 2


def command_parser() -> argparse.ArgumentParser:
    """The parser :func:`main` reads a command line with: every command's (:func:`build_parser`)
    and the options that stand before the command, ``--debug`` and ``--plugin`` (taken out of
    argv by main wherever they stand). Building it runs nothing and imports no plugin."""
    parser = build_parser()
    parser.add_argument("--debug", action="store_true", help="show tracebacks (for bug reports)")
    parser.add_argument("--plugin", action="append", metavar="MODULE_OR_FILE.py",
                        help=PLUGIN_HELP)
    return parser


def _main(argv: Sequence[str] | None) -> int:
    parser = command_parser()
    argv = list(sys.argv[1:] if argv is None else argv)
    # --debug is a flag that stands anywhere (taken out here, as --plugin is): given twice it
    # asks for the same thing again, as every flag of the parser (dbench.options._GivenOnce)
    debug = "--debug" in argv
    argv = [a for a in argv if a != "--debug"]
    try:
        argv, plugin_specs = split_plugin_args(argv)
    except DbenchInputError as exc:
        print(f"dbench: {exc}", file=sys.stderr)
        return 2
    args = parser.parse_args(argv)
    # before the command the parser reads it too, abbreviated (--deb) as argparse takes any
    # option: accepted, it must not be ignored
    debug = debug or args.debug
    # --device cpu|cuda also chooses where Mitsuba renders (the variant, part of every render's
    # cache key: dbench/datasets/mitsuba_env.py); sweep workers inherit it from the environment
    render_device = getattr(args, "device", None)
    # the renderer probes keep their verdict in the command's cache folder, and nowhere under
    # --no-cache (dbench/datasets/mitsuba_env.py); sweep workers inherit both
    from ..datasets.mitsuba_env import PROBE_STORE_ENV, forget_loads, forget_probes, probe_folder
    from ..datasets.mitsuba_log import QUIET_ENV, follow_quiet

    probe_store = ("none" if getattr(args, "no_cache", False) else getattr(args, "cache", None))
    saved = {k: os.environ.get(k) for k in ("DBENCH_RENDER_DEVICE", PROBE_STORE_ENV, QUIET_ENV)}
    if render_device in ("cpu", "cuda"):
        os.environ["DBENCH_RENDER_DEVICE"] = render_device
    if probe_store:
        os.environ[PROBE_STORE_ENV] = str(probe_store)
    # --quiet: Mitsuba's own log lines and Dr.Jit's start-up lines are kept in the command's log
    # beside its output (run.log, sweep.log, export.log, stress.log), not shown, and Dr.Jit
    # prints its errors alone (sweep workers inherit it: dbench/datasets/mitsuba_log.py)
    if getattr(args, "quiet", False) and args.command in LOGGED:
        os.environ[QUIET_ENV] = "1"
    else:
        os.environ.pop(QUIET_ENV, None)
    level = follow_quiet()  # the level a notebook had set is given back at the end
    forget_loads()  # a scene file's warnings in this command's log, though loaded before
    from ..io import missing_folders

    store = probe_folder()
    created = missing_folders(store) if store is not None else []
    code = 1
    try:
        _load_plugins(args, plugin_specs)
        code = args.func(args)
        return code
    except Exception as exc:  # noqa: BLE001 - one line, not a traceback (--debug shows it)
        from ..report import run_output

        if not run_output.terminated():
            code = _error_code(exc, debug)
            return code
        # the interrupt, turned into another error on its way (Mitsuba's "cannot set variant")
        print("dbench: interrupted", file=sys.stderr)
        return 130
    except KeyboardInterrupt:
        print("dbench: interrupted", file=sys.stderr)
        return 130
    finally:  # a command run in-process (tests, notebooks) leaves the environment as it was
        if code == 2 and created:  # refused: the cache folder the probes made goes again
            forget_probes(created)
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value
        follow_quiet(level)


def _error_code(exc: Exception, debug: bool) -> int:
    """One line on stderr and the exit code (module docstring) of an error that ended a
    command; ``debug`` re-raises an internal error for its traceback."""
    if isinstance(exc, (UnknownNameError, DbenchInputError)):
        print(f"dbench: {exc}", file=sys.stderr)
        return 2
    if isinstance(exc, RendererUnavailableError):
        print(f"dbench: {exc}", file=sys.stderr)
        return 3
    if isinstance(exc, PermissionError) and exc.filename and not debug:
        # a file or folder the user named that this user may not read: the input's problem
        print(f"dbench: cannot access {exc.filename}: {exc.strerror or 'permission denied'}",
              file=sys.stderr)
        return 2
    if debug:
        raise exc
    print(f"dbench: internal error: {type(exc).__name__}: {exc} (run again with --debug for the "
          "traceback)", file=sys.stderr)
    return 1


__all__ = ["build_parser", "command_parser", "main", "parse_params", "split_plugin_args"]
