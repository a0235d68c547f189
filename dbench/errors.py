"""Exceptions with messages a user can act on."""
from __future__ import annotations


class DbenchError(Exception):
    """Base class of every error dbench raises on purpose."""


class DbenchInputError(DbenchError, ValueError):
    """A buffer handed to dbench has the wrong shape, dtype or content.

    The message always names the buffer and the expected shape, e.g.
    ``albedo: expected shape (H, W, 3) = (64, 64, 3), got (64, 64)``.
    """


class UnknownNameError(DbenchError, KeyError):
    """An unknown method, scene or metric name; the message lists the valid names."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ""


class RendererUnavailableError(DbenchError, RuntimeError):
    """Mitsuba (or the variant a request needs) cannot run on this machine."""


class OutputError(DbenchInputError):
    """A result cannot be written where the user asked (full disk, quota, read-only or
    unwritable folder): the message names the path and the system's reason, e.g.
    ``cannot write results/run/metrics.csv: No space left on device`` (README.md, "Usage").
    """

    def __init__(self, path: object, reason: str) -> None:
        super().__init__(path, reason)  # both in args, so the error survives pickling
        self.path = path
        self.reason = reason

    def __str__(self) -> str:
        return f"cannot write {self.path}: {self.reason}"
