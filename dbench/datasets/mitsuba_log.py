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
"""
from __future__ import annotations

import logging
import os
import sys

#: Set (to "1") by the command line for a command run with ``--quiet``: Mitsuba's lines are
#: then kept (run.log, sweep.log, export.log, stress.log) and not shown.
QUIET_ENV = "DBENCH_QUIET"
#: The Python logger Mitsuba's lines go to.
LOGGER = "mitsuba"

#: The appender installed in this process (kept referenced: Mitsuba holds the C++ side only).
_installed: list = []


class _Terminal(logging.Handler):
    """Shows the ``mitsuba`` logger's lines on standard error unless :data:`QUIET_ENV` is set;
    being a handler, it also keeps Python's last-resort handler from printing them twice."""

    def emit(self, record: logging.LogRecord) -> None:
        if os.environ.get(QUIET_ENV):
            return
        try:
            print(f"mitsuba {record.levelname.lower()}: {record.getMessage()}", file=sys.stderr,
                  flush=True)
        except Exception:  # noqa: BLE001 - a log line never ends the command
            pass


def _logger() -> logging.Logger:
    log = logging.getLogger(LOGGER)
    if not any(isinstance(h, _Terminal) for h in log.handlers):
        log.addHandler(_Terminal(logging.WARNING))
    return log


def forward(mi, level, text: str) -> None:
    """One Mitsuba log line (``level`` an ``mi.LogLevel``, ``text`` formatted by Mitsuba's
    formatter without date and level, "[HDRFilm] ...") to the ``mitsuba`` logger."""
    py_level = logging.ERROR if level >= mi.LogLevel.Error else (
        logging.WARNING if level >= mi.LogLevel.Warn else logging.INFO)
    _logger().log(py_level, "%s", text.rstrip())


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


__all__ = ["LOGGER", "QUIET_ENV", "forward", "route"]
