"""One writer per sweep folder: the lock a ``dbench sweep`` holds on its ``--out`` while it runs.

Two sweeps writing into one folder would leave cells of two settings beside a ``sweep.json``
that describes only one of them (README.md, the ``dbench sweep`` paragraph). A sweep therefore
takes ``<out>/.sweep.lock`` before it reads or writes anything there, and a second sweep into the
same folder is refused with one line naming the holder (pid, host, since; exit 2).

The lock is an exclusive ``flock`` on that file: the operating system drops it when the holder's
process ends, however it ends, so a sweep killed with ``kill -9`` never leaves the folder locked.
The file also holds the holder's pid, host and start time, for the refusal message and for a
note when a later sweep finds the record of a holder that is gone. The holder removes the file
when it finishes. Where the file system has no ``flock``, the record alone decides: a record
whose pid is not running on this host is stale and is taken over with a note.
"""
from __future__ import annotations

import errno
import json
import os
import socket
import sys
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

from .. import io
from ..errors import DbenchInputError

LOCK_NAME = ".sweep.lock"

try:
    import fcntl
except ImportError:  # pragma: no cover - not POSIX: the pid record alone
    fcntl = None


def _record() -> dict:
    return {"pid": os.getpid(), "host": socket.gethostname(),
            "since": time.strftime("%Y-%m-%d %H:%M:%S %z"), "started": time.time()}


def _read_record(fd: int) -> dict:
    """The holder's record, or {} when the file is empty or not a record (a holder between
    creating and filling it: read again for a moment before giving up)."""
    for _ in range(20):
        try:
            raw = os.pread(fd, 4096, 0)
            value = json.loads(raw.decode("utf-8")) if raw.strip() else None
        except (OSError, ValueError):
            value = None
        if isinstance(value, dict):
            return value
        time.sleep(0.01)
    return {}


def _alive(pid: object) -> bool:
    if not isinstance(pid, int) or isinstance(pid, bool) or pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process that exists
        return True
    return True


def _holder_text(rec: dict) -> str:
    return (f"pid {rec.get('pid', '?')} on {rec.get('host', '?')}, since "
            f"{rec.get('since', '?')}")


def _refuse(out: Path, rec: dict) -> DbenchInputError:
    return DbenchInputError(
        f"--out {out}: another sweep is writing there ({_holder_text(rec)}); wait for it to "
        f"finish, or use another --out" if rec else
        f"--out {out}: another sweep is writing there (its lock file {out / LOCK_NAME} names "
        f"no holder yet); wait for it to finish, or use another --out")


def _note_stale(out: Path, rec: dict) -> None:
    if rec and rec.get("pid") != os.getpid():
        print(f"dbench: --out {out}: taking over the lock of a sweep that is no longer running "
              f"({_holder_text(rec)})", file=sys.stderr)


def _flock(fd: int) -> bool | None:
    """True: locked; False: another process holds it; None: the file system has no flock."""
    if fcntl is None:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        return True
    except OSError as exc:
        if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
            return False
        return None


def acquire(out: str | Path) -> int:
    """Take the lock of sweep folder ``out`` (which exists); returns the open lock file.
    Raises DbenchInputError naming the holder when another live sweep has it."""
    out = Path(out)
    path = out / LOCK_NAME
    for _ in range(50):
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise DbenchInputError(f"--out {out}: cannot create its lock file {path.name} "
                                   f"({exc.strerror or exc})") from None
        got = _flock(fd)
        if got is False:
            rec = _read_record(fd)
            os.close(fd)
            raise _refuse(out, rec)
        # A holder that finished removes the file; a file opened just before that removal is
        # no longer the lock (a newcomer creates another): open it again.
        try:
            same = os.stat(path).st_ino == os.fstat(fd).st_ino
        except FileNotFoundError:
            same = False
        if not same:
            os.close(fd)
            continue
        previous = _read_record(fd) if os.fstat(fd).st_size else {}
        if got is None and previous and _alive(previous.get("pid")) and \
                previous.get("host") == socket.gethostname() and \
                previous.get("pid") != os.getpid():
            os.close(fd)
            raise _refuse(out, previous)
        _note_stale(out, previous)
        data = (json.dumps(_record()) + "\n").encode("utf-8")
        os.ftruncate(fd, 0)
        os.pwrite(fd, data, 0)
        return fd
    raise DbenchInputError(f"--out {out}: its lock file {path.name} keeps changing; is another "
                           f"sweep starting there?")


def release(out: str | Path, fd: int) -> None:
    """Remove the lock file (while still holding it, so no newcomer locks a removed file) and
    close it, which drops the lock."""
    try:
        path = Path(out) / LOCK_NAME
        if os.stat(path).st_ino == os.fstat(fd).st_ino:
            path.unlink()
    except OSError:
        pass
    finally:
        os.close(fd)


@contextmanager
def hold(out: str | Path) -> Iterator[Path]:
    """Create folder ``out`` if needed, hold its lock for the block, release it after. The
    folders this call created (``out`` and the parents it lacked) are removed again when the
    block fails and left them empty (a refused sweep writes nothing: README.md, "Usage")."""
    out = Path(out)
    created = io.missing_folders(out)
    io.ensure_writable_dir(out, "--out")
    fd = acquire(out)
    ok = False
    try:
        yield out
        ok = True
    finally:
        release(out, fd)
        if not ok:
            io.remove_empty(created)


__all__ = ["LOCK_NAME", "acquire", "hold", "release"]
