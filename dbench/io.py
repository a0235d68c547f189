"""EXR, PNG and JSON reading and writing; every write is atomic (temporary name, then rename).

EXR files hold named buffers as channel groups: a buffer ``albedo`` of shape (H, W, 3) becomes
channels ``albedo.R``, ``albedo.G``, ``albedo.B``; a one-channel buffer ``depth`` becomes
``depth.Z``; transient (H, W, T, C) buffers are stored per bin as ``color.t0042.R`` and so on.
"""
from __future__ import annotations

import errno
import json
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Collection, Iterator

import numpy as np

from .errors import DbenchInputError, OutputError

_RGB = ("R", "G", "B")

#: errors of the user's situation rather than of dbench: the write becomes an OutputError
#: (one line naming the path, exit 2) instead of an internal error
WRITE_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EROFS, errno.EACCES, errno.EPERM,
                          errno.EFBIG, errno.ENAMETOOLONG})


def output_error(exc: BaseException, path: str | os.PathLike) -> OutputError | None:
    """The OutputError naming ``path`` for a failed write of the user's situation (full disk,
    quota, read-only or unwritable folder), else None. OpenEXR reports these as a RuntimeError
    quoting the system's message, so that message is recognised too."""
    if isinstance(exc, OutputError):
        return exc
    if isinstance(exc, OSError) and exc.errno in WRITE_ERRNOS:
        return OutputError(path, exc.strerror or str(exc))
    if isinstance(exc, RuntimeError):
        for code in WRITE_ERRNOS:
            if os.strerror(code) in str(exc):
                return OutputError(path, os.strerror(code))
    return None


@contextmanager
def atomic_path(path: str | os.PathLike, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it onto ``path`` only if the block succeeds.

    A killed process leaves at most a ``.tmp`` file that no reader mistakes for the real one.
    A full disk or an unwritable folder raises an OutputError naming ``path`` (and leaves no
    ``.tmp`` file).
    """
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.",
                                   suffix=suffix or f".tmp{path.suffix}", dir=path.parent)
        os.close(fd)
    except OSError as exc:
        error = output_error(exc, path)
        if error is None:
            raise
        raise error from None
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        # mkstemp creates 0600; a result file gets the mode the umask gives any new file.
        os.chmod(tmp_path, 0o666 & ~_umask())
        os.replace(tmp_path, path)
    except (OSError, RuntimeError) as exc:
        error = output_error(exc, path)
        if error is None:
            raise
        raise error from None
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def ensure_writable_dir(path: str | os.PathLike, what: str) -> Path:
    """Create folder ``path`` (and parents) and check that files can be written in it; a
    DbenchInputError naming ``what`` otherwise (before any work is done), and then the folders
    this check created are gone again."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise DbenchInputError(f"{what} {path}: exists and is not a folder")
    created = missing_folders(path)
    try:
        path.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=".write-probe-", dir=path)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        remove_empty(created)
        raise DbenchInputError(f"{what} {path}: cannot write there ({exc.strerror or exc})") \
            from None
    return path


def ensure_writable_file(path: str | os.PathLike, what: str) -> Path:
    """Check that file ``path`` can be written (its folder created where missing), before any
    work is done: a DbenchInputError naming ``what`` when it is a folder, lies under a file,
    or cannot be written."""
    path = Path(path)
    if path.is_dir():
        raise DbenchInputError(f"{what} {path}: is a folder; give a file name")
    ensure_writable_dir(path.parent, what)
    if path.exists() and not os.access(path, os.W_OK):
        raise DbenchInputError(f"{what} {path}: cannot write there (read-only file)")
    return path


def write_text(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` as UTF-8 whatever the locale (a C/ASCII locale must not fail on "×")."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def write_json(path: str | os.PathLike, obj: Any) -> None:
    write_text(path, json.dumps(obj, indent=2, sort_keys=True, default=_json_default) + "\n")


def read_json(path: str | os.PathLike) -> Any:
    return json.loads(Path(path).read_text(encoding="utf-8"))


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, (set, frozenset)):
        return sorted(obj)
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def _channel_names(name: str, array: np.ndarray) -> list[tuple[str, tuple]]:
    """(channel name, index into the array) for every 2D slice of a buffer."""
    if array.ndim == 2:
        return [(f"{name}.Z", (slice(None), slice(None)))]
    if array.ndim == 3:
        c = array.shape[2]
        labels = ("Z",) if c == 1 else _RGB if c == 3 else tuple(f"c{i}" for i in range(c))
        return [(f"{name}.{lab}", (slice(None), slice(None), i)) for i, lab in enumerate(labels)]
    if array.ndim == 4:
        out = []
        for t in range(array.shape[2]):
            for ch, idx in _channel_names(f"{name}.t{t:04d}", array[:, :, t]):
                out.append((ch, (slice(None), slice(None), t) + idx[2:]))
        return out
    raise DbenchInputError(f"{name}: expected (H, W), (H, W, C) or (H, W, T, C), "
                           f"got {array.shape}")


def write_exr(path: str | os.PathLike, buffers: dict[str, np.ndarray],
              compress: bool = True, raw: Collection[str] = ()) -> None:
    """Write named float buffers (same H, W) into one float32 EXR, atomically: ZIP-compressed,
    or, with ``compress=False``, uncompressed (for noisy colour, whose float mantissas are
    noise: ZIP kept 92 % of a 256² render's bytes for 3× the write time and 2.3× the read).

    ``raw``: buffers written uncompressed in a second part of the file (a multi-part EXR,
    which :func:`read_exr` and OpenEXR's tools read as one), the others as ``compress`` says:
    a sequence frame's noisy colour beside its G-buffer, which ZIP shrinks about 5× (256²:
    22–25 ms against 28–32 ms a write, 7–9 ms against 10 ms a read)."""
    import OpenEXR

    if not buffers:  # (an EXR holds at least one channel)
        raise ValueError(f"write_exr: no buffers to write to {path}")
    raw = set(raw) if compress else set()  # (uncompressed anyway: one part)
    hw = None
    parts = []
    for names, zipped in (([n for n in buffers if n not in raw], compress),
                          ([n for n in buffers if n in raw], False)):
        channels: dict[str, np.ndarray] = {}
        for name in names:
            array = np.asarray(buffers[name], dtype=np.float32)
            if hw is None:
                hw = array.shape[:2]
            elif array.shape[:2] != hw:
                raise DbenchInputError(f"{name}: expected height and width {hw}, got "
                                       f"{array.shape[:2]}")
            for ch, idx in _channel_names(name, array):
                channels[ch] = np.ascontiguousarray(array[idx])
        if channels:
            header = {"compression": OpenEXR.ZIP_COMPRESSION if zipped else
                      OpenEXR.NO_COMPRESSION, "type": OpenEXR.scanlineimage}
            parts.append((header, channels, "zip" if zipped else "raw"))
    with atomic_path(path, suffix=".tmp.exr") as tmp:
        exr = OpenEXR.File(*parts[0][:2]) if len(parts) == 1 else \
            OpenEXR.File([OpenEXR.Part(*part) for part in parts])
        with exr as f:
            f.write(str(tmp))


def read_exr(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Read an EXR written by :func:`write_exr` back into named (H, W, C) / (H, W, T, C) buffers."""
    import OpenEXR

    with OpenEXR.File(str(path)) as f:  # every part's channels (write_exr's ``raw``)
        raw = {k: np.array(v.pixels, dtype=np.float32) for part in f.parts
               for k, v in part.channels.items()}
    groups: dict[str, dict[str, np.ndarray]] = {}
    for ch, pix in raw.items():
        if pix.ndim == 3:
            # OpenEXR's Python binding already merges "name.R/G/B" into one (H, W, 3) channel.
            groups.setdefault(ch, {}).update({c: pix[..., i] for i, c in enumerate(_RGB)})
            continue
        buf, _, label = ch.rpartition(".")
        groups.setdefault(buf or ch, {})[label] = pix
    out: dict[str, np.ndarray] = {}
    timed: dict[str, dict[int, np.ndarray]] = {}
    for buf, chans in groups.items():
        stacked = _stack_channels(chans)
        head, _, tail = buf.rpartition(".")
        if head and tail.startswith("t") and tail[1:].isdigit():
            timed.setdefault(head, {})[int(tail[1:])] = stacked
        else:
            out[buf] = stacked
    for buf, bins in timed.items():
        out[buf] = np.stack([bins[t] for t in sorted(bins)], axis=2)
    return out


def _stack_channels(chans: dict[str, np.ndarray]) -> np.ndarray:
    if set(chans) == {"Z"}:
        return chans["Z"][..., None]
    if set(chans) == set(_RGB):
        return np.stack([chans[c] for c in _RGB], axis=-1)
    keys = sorted(chans, key=lambda k: int(k[1:]) if k[1:].isdigit() else k)
    return np.stack([chans[k] for k in keys], axis=-1)


def write_png(path: str | os.PathLike, image: np.ndarray) -> None:
    """Write an (H, W, 3) or (H, W) image in [0, 1] (clipped) as an 8-bit PNG, atomically."""
    import matplotlib.image as mpimg

    img = np.clip(np.nan_to_num(np.asarray(image, np.float32)), 0.0, 1.0)
    with atomic_path(path, suffix=".tmp.png") as tmp:
        mpimg.imsave(str(tmp), img, format="png")


def missing_folders(path: str | Path) -> list[Path]:
    """``path`` and its parents that do not exist yet, deepest first (what creating ``path``
    creates)."""
    path = Path(path).absolute()
    return [p for p in (path, *path.parents) if not p.exists()]


def remove_empty(folders: list[Path]) -> None:
    """Remove ``folders`` (deepest first) as long as they are empty: a folder that holds
    anything, someone else's file included, stays, and so do its parents."""
    for folder in folders:
        try:
            folder.rmdir()
        except OSError:
            return
