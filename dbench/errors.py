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
