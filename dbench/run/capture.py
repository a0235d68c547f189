"""Library warnings kept out of the terminal and written to the run's ``run.log``.

NumPy's RuntimeWarnings on NaN inputs, numba's performance notes, a library's ``logging``
warnings, Mitsuba's own log lines (dbench/datasets/mitsuba_log.py): none of them is the run's
result, and printed between the progress lines they bury the headline (README.md, "Usage").
Inside :func:`library_warnings` every :mod:`warnings` warning and every ``logging`` record of
level WARNING or above is kept, in order, as one line; the run writes them to ``run.log`` and
counts them in ``report.md``.
"""
from __future__ import annotations

import contextlib
import logging
import warnings
from typing import Iterator


class _Keep(logging.Handler):
    def __init__(self, lines: list[str]) -> None:
        super().__init__(logging.WARNING)
        self.lines = lines

    def emit(self, record: logging.LogRecord) -> None:
        try:
            self.lines.append(f"{record.levelname} {record.name}: {record.getMessage()}")
        except Exception:  # noqa: BLE001 - a malformed record must not end the run
            self.lines.append(f"{record.levelname} {record.name}: {record.msg!r}")


@contextlib.contextmanager
def library_warnings() -> Iterator[list[str]]:
    """Collects the warnings raised inside the block as lines (``category file:line: text``,
    ``LEVEL logger: text``) into the list it yields; nothing of them reaches the terminal
    (Mitsuba's lines are also shown unless ``--quiet``: dbench/datasets/mitsuba_log.py). In
    nested blocks the innermost keeps each line."""
    lines: list[str] = []
    root = logging.getLogger()
    handler = _Keep(lines)
    with warnings.catch_warnings():
        warnings.simplefilter("always")  # every occurrence is counted, not only the first

        def keep(message, category, filename, lineno, file=None, line=None):  # noqa: ANN001
            lines.append(f"{category.__name__} {filename}:{lineno}: {message}")

        warnings.showwarning = keep
        # the innermost block keeps a record, as catch_warnings does for warnings: a sweep's
        # group run in the sweep's own process is counted once, not by both blocks
        outer = [h for h in root.handlers if isinstance(h, _Keep)]
        for h in outer:
            root.removeHandler(h)
        # a root handler also keeps Python's last-resort handler from printing records
        root.addHandler(handler)
        try:
            yield lines
        finally:
            root.removeHandler(handler)
            for h in outer:
                root.addHandler(h)


def _count(n: int) -> str:
    """``1 library warning``, ``3 library warnings``."""
    return f"{n} library warning{'s' if n != 1 else ''}"


def log_text(lines: list[str]) -> str:
    """``run.log``: one warning a line, or a line saying there were none."""
    if not lines:
        return "no library warnings\n"
    return f"{_count(len(lines))}\n" + "".join(f"{ln}\n" for ln in lines)


def count_text(lines: list[str], where: str = "run.log") -> str:
    """``3 library warnings, see run.log`` (``where``: the log that holds them; or ``no
    library warnings``)."""
    return f"{_count(len(lines))}, see {where}" if lines else "no library warnings"
