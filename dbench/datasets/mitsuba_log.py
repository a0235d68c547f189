"""Mitsuba's log lines, one home: Python's ``logging``, not Mitsuba's own terminal appender.

Mitsuba prints its warnings itself (a deprecated parameter of a user's scene file, "The
"compensate" ... parameter has been removed and is now ignored") from C++ straight to standard
output, past ``--quiet`` and past the run's files. :func:`route` replaces that appender, once a
process, by one that hands every line to the Python logger ``mitsuba`` (level WARNING, or ERROR
for Mitsuba's errors): inside :func:`dbench.run.capture.library_warnings` it is kept, in order,
with the other libraries' warnings in ``run.log`` / ``sweep.log`` (under ``--quiet``,
``export.log`` / ``stress.log``) and counted;
and it is shown on standard error as Mitsuba showed it, unless the command runs under
``--quiet`` (README.md, "Usage"): the command line sets :data:`QUIET_ENV` for the command's
duration, and a sweep's worker processes inherit it.

Dr.Jit writes its own warnings from C++ to standard error, past Mitsuba's logger: at its import
("jit_init(): the HOME environment variable is not set, disabling the kernel cache", "could not
use ... as the kernel cache directory": renders then compile every kernel anew) and, rarely,
later (its memory cache flushed). No Dr.Jit call can come before its import, so
:func:`drjit_start` keeps standard error aside while Dr.Jit and Mitsuba start and hands those
lines to the Python logger ``drjit``, kept and shown as Mitsuba's are (as Dr.Jit words them);
after the import :func:`follow_quiet` sets Dr.Jit's own level (``dr.set_log_level``) to errors
alone under ``--quiet``.

Scenes are loaded inside :func:`loading` (:func:`dbench.datasets.mitsuba_env.scene_cache`). A
load that repeats one this process made before (the same loader and arguments, its objects
dropped meanwhile by :func:`dbench.datasets.mitsuba_env.focus`: a scene file read when a sweep
checks its scenes and loaded again for its renders after other scenes') gives the first load's
warnings, shown and kept then, so they are not forwarded again; nor are, in a sweep's pool
worker or Ray task, the warnings the sweep process forwarded from its own loads
(:func:`load_lines`, :func:`inherit`), which the worker's loads of the same scenes repeat
(docs/mitsuba.md §3).
"""
from __future__ import annotations

import contextlib
import logging
import os
import sys
import tempfile
from typing import Iterator

#: Set (to "1") by the command line for a command run with ``--quiet``: Mitsuba's lines are
#: then kept (run.log, sweep.log, export.log, stress.log) and not shown.
QUIET_ENV = "DBENCH_QUIET"
#: The Python logger Mitsuba's lines go to.
LOGGER = "mitsuba"
#: The Python logger Dr.Jit's lines at its import go to.
DRJIT_LOGGER = "drjit"

#: The appender installed in this process (kept referenced: Mitsuba holds the C++ side only).
_installed: list = []
#: One entry per :func:`loading` block open, innermost last: whether its load repeats one made
#: before (a module-wide stack, not a thread's: Mitsuba loads a file's objects on its own
#: threads, which log from there).
_loading: list[bool] = []
#: The warnings forwarded while this process loaded scenes for the first time, in order.
_load_lines: list[str] = []
#: In a sweep's pool worker or Ray task: the sweep process's :data:`_load_lines` (:func:`inherit`).
_inherited: set[str] = set()


class _Terminal(logging.Handler):
    """Shows a renderer logger's lines on standard error unless :data:`QUIET_ENV` is set
    (Mitsuba's after "mitsuba warning: ", Dr.Jit's as it printed them); being a handler, it
    also keeps Python's last-resort handler from printing them twice."""

    def emit(self, record: logging.LogRecord) -> None:
        if os.environ.get(QUIET_ENV):
            return
        text = record.getMessage()
        if record.name == LOGGER:
            text = f"mitsuba {record.levelname.lower()}: {text}"
        try:
            print(text, file=sys.stderr, flush=True)
        except Exception:  # noqa: BLE001 - a log line never ends the command
            pass


def _logger(name: str = LOGGER) -> logging.Logger:
    log = logging.getLogger(name)
    if not any(isinstance(h, _Terminal) for h in log.handlers):
        log.addHandler(_Terminal(logging.WARNING))
    return log


@contextlib.contextmanager
def drjit_start() -> Iterator[None]:
    """Around the first import of Dr.Jit and Mitsuba and the choice of the variant (which waits
    for Dr.Jit's start): what is written to standard error meanwhile (Dr.Jit's start-up
    warnings) goes to the ``drjit`` logger, one record a line, once the block ends. Where Dr.Jit
    is already imported, nothing is kept aside."""
    if "drjit" in sys.modules:
        yield
        return
    sys.stderr.flush()
    with tempfile.TemporaryFile() as kept:
        saved = os.dup(2)
        os.dup2(kept.fileno(), 2)
        try:
            yield
        finally:
            try:
                sys.stderr.flush()
                dr = sys.modules.get("drjit")
                if dr is not None:  # Dr.Jit starts beside its import: wait for its lines
                    dr.has_backend(dr.JitBackend.LLVM)
            finally:
                os.dup2(saved, 2)
                os.close(saved)
            kept.seek(0)
            text = kept.read().decode("utf-8", errors="replace")
            for line in text.splitlines():
                if line.strip():
                    _logger(DRJIT_LOGGER).warning("%s", line.rstrip())


def follow_quiet(level=None):
    """Dr.Jit's own level for what it prints after its import: ``level`` where given (the one
    a command found, given back when it ends), else errors alone while :data:`QUIET_ENV` is
    set, else warnings (its default); nothing where Dr.Jit is not imported (:func:`drjit_start`
    then covers its start). Returns the level it replaced (None: not imported)."""
    dr = sys.modules.get("drjit")
    if dr is None or not hasattr(dr, "set_log_level"):
        return None
    before = dr.log_level()
    if level is None:
        level = dr.LogLevel.Error if os.environ.get(QUIET_ENV) else dr.LogLevel.Warn
    dr.set_log_level(level)
    return before


def forward(mi, level, text: str) -> None:
    """One Mitsuba log line (``level`` an ``mi.LogLevel``, ``text`` formatted by Mitsuba's
    formatter without date and level, "[HDRFilm] ...") to the ``mitsuba`` logger."""
    py_level = logging.ERROR if level >= mi.LogLevel.Error else (
        logging.WARNING if level >= mi.LogLevel.Warn else logging.INFO)
    text = text.rstrip()
    if _loading and py_level < logging.ERROR:
        if _loading[-1] or text in _inherited:  # forwarded by the first load already
            return
        _load_lines.append(text)
    _logger().log(py_level, "%s", text)


@contextlib.contextmanager
def loading(again: bool = False):
    """Inside the block a scene is loaded; ``again``: the load repeats one this process made
    before, and Mitsuba's warnings are dropped (module docstring). Errors are always
    forwarded."""
    _loading.append(bool(again))
    try:
        yield
    finally:
        _loading.pop()


def load_lines() -> tuple[str, ...]:
    """The warnings this process's first loads of scenes forwarded (for :func:`inherit`)."""
    return tuple(dict.fromkeys(_load_lines))


def forget() -> None:
    """Forget the lines earlier loads forwarded or a sweep process handed on (a new command:
    :func:`dbench.datasets.mitsuba_env.forget_loads`)."""
    _load_lines.clear()
    _inherited.clear()


def inherit(lines) -> None:
    """In a sweep's pool worker or Ray task: the sweep process's :func:`load_lines`, kept there,
    are not forwarded again when the worker's loads of the same scenes repeat them."""
    _inherited.update(str(line) for line in lines)


def route(mi) -> None:
    """Send Mitsuba's log lines through :func:`forward` instead of its stream appender; once a
    process (a second call does nothing). Mitsuba's progress bars are dropped: dbench shows its
    own (``--quiet``: none)."""
    if _installed:
        return

    class _Forward(mi.Appender):
        def append(self, level, text: str) -> None:
            forward(mi, level, text)

        def log_progress(self, *args) -> None:
            pass

    logger = mi.logger()
    # run.log keeps the lines in order, with the level Python's record carries
    logger.formatter().set_has_date(False)
    logger.formatter().set_has_log_level(False)
    appender = _Forward()
    logger.clear_appenders()
    logger.add_appender(appender)
    _installed.append(appender)
    _logger()


__all__ = ["DRJIT_LOGGER", "LOGGER", "QUIET_ENV", "drjit_start", "follow_quiet", "forget",
           "forward", "inherit", "load_lines", "loading", "route"]
