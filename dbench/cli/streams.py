"""Standard output and error that never end a command (README.md, "Usage").

A reader that goes away (``dbench run ... | head -1``) or a full device (``> /dev/full``) costs
only the printed text: the command goes on and its files are written. Text the terminal's
encoding cannot show (an ASCII locale) is printed with backslash escapes instead of failing.
"""
from __future__ import annotations

import codecs
import errno
import os
import sys
from contextlib import contextmanager
from typing import Any, Iterator


class GuardedStream:
    """A text stream wrapper whose writes cannot raise: after the first failure it drops
    everything and keeps the error in :attr:`lost`."""

    def __init__(self, stream: Any) -> None:
        self._stream = stream
        self.lost: OSError | None = None

    def write(self, text: str) -> int:
        if self.lost is not None or self._stream is None:  # None: started with it closed
            return len(text)
        try:
            return self._stream.write(text)
        except UnicodeEncodeError:
            # a stream that could not be reconfigured: escape what its encoding cannot hold
            enc = getattr(self._stream, "encoding", None) or "ascii"
            return self.write(text.encode(enc, "backslashreplace").decode(enc))
        except OSError as exc:
            self._drop(exc)
            return len(text)

    def writelines(self, lines: Any) -> None:
        for line in lines:
            self.write(line)

    def flush(self) -> None:
        if self.lost is not None or self._stream is None:
            return
        try:
            self._stream.flush()
        except OSError as exc:
            self._drop(exc)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._stream, name)

    def _drop(self, exc: OSError) -> None:
        self.lost = exc
        # Python flushes the standard streams again at exit: with the descriptor pointing at
        # the null device that flush neither fails nor prints "Exception ignored ..."
        try:
            fd = self._stream.fileno()
            devnull = os.open(os.devnull, os.O_WRONLY)
            try:
                os.dup2(devnull, fd)
            finally:
                os.close(devnull)
        except (OSError, ValueError, AttributeError):
            pass  # no descriptor (a test's captured stream): dropping the text is enough


def _escape_unencodable(stream: Any) -> None:
    """Let a stream whose encoding is not UTF-8 (LC_ALL=C) print "×" as ``\\xd7``."""
    try:
        if codecs.lookup(stream.encoding).name != "utf-8":
            stream.reconfigure(errors="backslashreplace")
    except (AttributeError, LookupError, TypeError, ValueError):
        pass  # not a TextIOWrapper: GuardedStream.write escapes instead


@contextmanager
def guarded() -> Iterator[tuple[GuardedStream, GuardedStream]]:
    """Replace sys.stdout and sys.stderr by GuardedStream wrappers for the block (the
    originals come back after it, flushed)."""
    saved = sys.stdout, sys.stderr
    for stream in saved:
        if stream is not None:
            _escape_unencodable(stream)
    out, err = GuardedStream(saved[0]), GuardedStream(saved[1])
    sys.stdout, sys.stderr = out, err
    try:
        yield out, err
    finally:
        out.flush()
        err.flush()
        sys.stdout, sys.stderr = saved


def reader_gone(exc: OSError | None) -> bool:
    """Whether a lost stream's error means only that nobody reads it any more (a closed pipe):
    nothing to report, unlike a full disk."""
    return exc is not None and (isinstance(exc, BrokenPipeError) or exc.errno == errno.EPIPE)
