"""The output folder of ``dbench run``, written whole or not at all (README.md, "Usage").

Every file of a run goes into a temporary sibling ``<out>.partial-<pid>``; only when all of
them are written does that folder take the place of ``<out>`` (an earlier run's folder there is
renamed aside, the new one renamed in, then the old one deleted). A failure or Ctrl-C removes
the temporary folder, so ``<out>`` is either the earlier run's folder, untouched, or the new
one, complete, and never a mix of the two.
"""
from __future__ import annotations

import errno
import os
import shutil
import signal
import threading
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

from ..errors import DbenchInputError, OutputError
from ..io import ensure_writable_dir, output_error

#: the file every run folder holds; a folder without it is not replaced
MARKER = "run.json"

#: set by SIGTERM inside :func:`staged` (and by SIGINT or SIGTERM anywhere inside
#: :func:`interrupts_flagged`); cleared when the next block or command starts
_terminated = threading.Event()
#: whether a command's :func:`interrupts_flagged` is in force (its handlers serve the blocks)
_command_scope = threading.Event()


class Terminated(KeyboardInterrupt):
    """SIGTERM inside :func:`staged`, raised as an interrupt (exit 130). A subclass, never a
    bare KeyboardInterrupt: CPython marks a bare one that leaves code it ran from a string as
    unhandled, and a process so marked kills itself with SIGINT at exit, whatever exit code
    dbench returned."""


@contextmanager
def _raising_handlers(signals: tuple[int, ...]) -> Iterator[None]:
    """Each of ``signals`` sets the flag :func:`terminated` reads and raises
    :class:`Terminated` inside the block; the handlers before it are restored afterwards. Only
    the main thread can set handlers; a signal the process was started ignoring stays ignored."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {sig: signal.getsignal(sig) for sig in signals}

    def interrupt(signum, frame):
        _terminated.set()
        raise Terminated(f"stopped by {signal.Signals(signum).name}")  # said in sweep.json
    _terminated.clear()
    for sig, handler in previous.items():
        if handler is not signal.SIG_IGN:
            signal.signal(sig, interrupt)
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler if handler is not None else signal.SIG_DFL)


@contextmanager
def interrupts_flagged() -> Iterator[None]:
    """For a whole command (dbench/cli): Ctrl-C and SIGTERM raise :class:`Terminated` and set
    the flag :func:`terminated` reads, so an interrupt that a library turns into another error
    on its way (Mitsuba's variant being set: "returned a result with an exception set") or
    swallows (a ``__del__``) still ends the command as interrupted."""
    with _raising_handlers((signal.SIGINT, signal.SIGTERM)):
        _command_scope.set()
        try:
            yield
        finally:
            _command_scope.clear()


def terminated() -> bool:
    """Whether a SIGTERM arrived during the current or last :func:`staged` block, or a SIGINT
    or SIGTERM during the current or last command (:func:`interrupts_flagged`) (its
    interrupt may have been swallowed where Python ignores exceptions: a weakref callback, a
    ``__del__``, a library's catch-all)."""
    return _terminated.is_set()

#: errors that are a write problem wherever they come from; EACCES and the like only count
#: for paths inside the run folder (elsewhere they may come from reading an input)
_DISK_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EROFS})


def check_out(out: str | os.PathLike, what: str = "--out") -> Path:
    """The folder a run will replace, checked before any work: ``out`` must be absent, empty or
    an earlier run's folder (it holds ``run.json``); anything else is refused, never deleted.
    A link to a folder is followed, so the link keeps naming the new run."""
    out = Path(out)
    if out.is_symlink() and out.is_dir():
        out = out.resolve()
    if out.exists() or out.is_symlink():
        if not out.is_dir():
            raise DbenchInputError(f"{what} {out}: exists and is not a folder")
        try:
            foreign = any(out.iterdir()) and not (out / MARKER).is_file()
        except OSError as exc:
            raise DbenchInputError(f"{what} {out}: cannot read it ({exc.strerror or exc})") \
                from None
        if foreign:
            raise DbenchInputError(
                f"{what} {out}: exists and is not a dbench run folder (no {MARKER}); "
                "choose a new folder or empty this one")
    # the run is written beside out and renamed into place: out's parent is what must be
    # writable (the message names that folder)
    ensure_writable_dir(out.parent, what)
    return out


@contextmanager
def staged(out: str | os.PathLike, what: str = "--out") -> Iterator[Path]:
    """Yield the temporary folder to write a run into; put it in place of ``out`` when the
    block ends normally, delete it when the block raises (KeyboardInterrupt included).

    A full disk or an unwritable folder, inside the block or while putting the folder in
    place, raises an OutputError naming the file as it would lie in ``out``. SIGTERM ends the
    block as Ctrl-C does (KeyboardInterrupt, exit 130), so it too leaves no temporary folder."""
    out = check_out(out, what)
    stage = out.parent / f"{out.name}.partial-{os.getpid()}"
    try:
        if stage.exists():  # left by an earlier process that had the same id and was killed
            shutil.rmtree(stage)
        stage.mkdir()
    except OSError as exc:
        error = _as_output_error(exc, stage, out)
        if error is None:
            raise
        raise error from None
    try:
        with _terminate_as_interrupt():
            yield stage
            if _terminated.is_set():  # the interrupt was swallowed: the run still ends here
                raise Terminated
            _swap_in(stage, out)
    except BaseException as exc:
        shutil.rmtree(stage, ignore_errors=True)
        error = _as_output_error(exc, stage, out)
        if error is None:
            raise
        raise error from None


@contextmanager
def _terminate_as_interrupt() -> Iterator[None]:
    """SIGTERM raises :class:`Terminated` for the block, so the cleanup above runs (by default it
    kills the process on the spot). Not SystemExit: a method's sys.exit is caught as that
    method's failure (dbench/cli/run.py), a termination must end the run."""
    if _command_scope.is_set():
        yield  # a command's handlers (interrupts_flagged) already do this, flag included
        return
    with _raising_handlers((signal.SIGTERM,)):
        yield


def _swap_in(stage: Path, out: Path) -> None:
    """Rename ``stage`` to ``out``; an earlier folder at ``out`` is renamed aside first and
    deleted only once the new one is in place (put back if the rename fails)."""
    old = None
    if out.exists():
        old = out.parent / f"{out.name}.old-{os.getpid()}"
        if old.exists():
            shutil.rmtree(old)
        os.rename(out, old)
    try:
        os.rename(stage, out)
    except BaseException:
        if old is not None:
            os.rename(old, out)
        raise
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def _as_output_error(exc: BaseException, stage: Path, out: Path) -> OutputError | None:
    """The OutputError for a failed write, its path moved from ``stage`` to ``out`` (the
    temporary name means nothing to the user), or None for any other exception."""
    if isinstance(exc, OSError):
        name = exc.filename
        inside = name is not None and _relative(Path(os.fsdecode(name)), stage) is not None
        if exc.errno not in _DISK_ERRNOS and not inside:
            return None
        error = output_error(exc, name if name is not None else out)
    elif isinstance(exc, OutputError):
        error = exc
    else:
        return None
    if error is None:
        return None
    rel = _relative(Path(os.fspath(error.path)), stage)
    return OutputError(out / rel if rel is not None else error.path, error.reason)


def _relative(path: Path, folder: Path) -> Path | None:
    try:
        return path.relative_to(folder)
    except ValueError:
        return None
