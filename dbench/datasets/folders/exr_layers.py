"""Raw EXR channels and the alias table that maps other tools' channel names to dbench buffers.

:mod:`dbench.io` reads files dbench wrote; folders users bring (docs/formats.md §1-2) name
their channels in several conventions, so this module reads channels by their raw names
(``separate_channels=True``: the binding would otherwise merge ``R,G,B,A`` into one ``RGBA``
array and ``X.R/G/B`` into ``X``) and resolves them through one small table.

A channel name splits into a *layer* and a *component*: ``albedo.R`` → (``albedo``, ``R``),
``dd.y.T`` → (``dd.y``, ``T``); pbrt-v4's undotted ``Px``, ``Nx``, ``Nsx`` → (``P``, ``x``),
(``N``, ``x``), (``Ns``, ``x``); a bare ``R``, ``G``, ``B``, ``A``, ``Y`` or ``Z`` has the layer
``""``. Layers and components are matched case-insensitively.

Alias table (layer → buffer; "priority" decides when two layers of one file give one buffer):

============  ==========================================================  ==========
buffer        layers                                                      components
============  ==========================================================  ==========
color         bare ``R,G,B`` (``A`` ignored), ``color``, ``rgb``,          R,G,B
              ``rgba``, ``beauty``
albedo        ``albedo``, ``alb``                                         R,G,B
normal        shading, priority 2: ``ns``, ``nn``, ``sh_normal``,         X,Y,Z or
              ``shading_normal``, ``normal``, ``nrm``;                    R,G,B
              geometric, priority 1: ``n``, ``ng``, ``geo_normal``
depth         ``depth``, ``dd``, ``z``, a bare ``Z``, and any layer whose  one channel
              only channel is ``T`` (Mitsuba's depth type)
position      ``position``, ``pos``, ``p``, ``pp``                        X,Y,Z or R,G,B
emitter       ``emitter``                                                 one channel
variance      ``variance``, ``var`` (σ² of one sample, pbrt-v4)           R,G,B
motion        ``motion``, ``mv``, ``motionvector``                        c0,c1 / X,Y / U,V / R,G
============  ==========================================================  ==========

Everything else (``RelativeVariance``, ``dzdx``, ``dzdy``, ``uv``, bare ``A`` / ``Y``, Mitsuba
layers of unknown name with ``X,Y,Z`` components, which could be normals, positions or
``dp_du``) is left unused and reported. A file holding one feature (``<name>_<spp>.<tag>.exr``)
needs no alias: its buffer is given by the tag, and its single layer with the right channel
count is taken (a layer named after the buffer wins when there are several).
"""
from __future__ import annotations

import errno
import io
import os
import re
import sys
import tempfile
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from ...errors import DbenchInputError
from ...io import atomic_path

#: Channel count of every buffer a folder can hold ("variance": σ² per sample of the colour).
CHANNELS = {"color": 3, "albedo": 3, "normal": 3, "depth": 1, "position": 3, "emitter": 1,
            "variance": 3, "motion": 2}

#: Layer name (lower case) → (buffer, priority).
ALIASES: dict[str, tuple[str, int]] = {
    "color": ("color", 1), "rgb": ("color", 1), "rgba": ("color", 1), "beauty": ("color", 1),
    "albedo": ("albedo", 1), "alb": ("albedo", 1),
    "ns": ("normal", 2), "nn": ("normal", 2), "sh_normal": ("normal", 2),
    "shading_normal": ("normal", 2), "normal": ("normal", 2), "nrm": ("normal", 2),
    "n": ("normal", 1), "ng": ("normal", 1), "geo_normal": ("normal", 1),
    "depth": ("depth", 1), "dd": ("depth", 1), "z": ("depth", 1),
    "position": ("position", 1), "pos": ("position", 1), "p": ("position", 1),
    "pp": ("position", 1),
    "emitter": ("emitter", 1),
    "variance": ("variance", 1), "var": ("variance", 1),
    "motion": ("motion", 1), "mv": ("motion", 1), "motionvector": ("motion", 1),
}

#: Accepted component sets, in buffer channel order, per channel count.
COMPONENTS = {3: (("r", "g", "b"), ("x", "y", "z")),
              2: (("c0", "c1"), ("x", "y"), ("u", "v"), ("r", "g")),
              1: (("z",), ("t",), ("y",))}

_PBRT = re.compile(r"(ns|n|p)([xyz])", re.I)


@dataclass(frozen=True)
class Layer:
    """Where one buffer lives: ``file`` (a path) and its raw channel names in buffer order."""

    file: Path
    buffer: str
    channels: tuple[str, ...]
    priority: int = 1


def _check_readable(path: Path) -> None:
    """Refuse a file this user may not read before OpenEXR does: its C library prints its own
    line to stderr first, and the user would get two (PermissionError: one line, exit 2)."""
    if path.is_file() and not os.access(path, os.R_OK):
        raise PermissionError(errno.EACCES, "Permission denied", str(path))


#: An EXR data window: ((x min, y min), (x max, y max)), inclusive.
Window = tuple[tuple[int, int], tuple[int, int]]


def _flush_c_stdio() -> None:
    """Flush the C library's stdio buffers: text it wrote to a descriptor that is a file or a
    pipe waits there, and must land on the side of the swap it was written on."""
    try:
        import ctypes

        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError, TypeError):
        pass  # no C library by that name (Windows): nothing of it to flush


@contextmanager
def _library_output() -> Iterator[list[str]]:
    """Capture what OpenEXR prints during the block: its C library on file descriptors 1 and
    2 (``EXR_ERR_BAD_CHUNK_LEADER`` on stderr), its binding through Python's ``sys.stdout``
    ("Warning: Exception raised reading pixel data").

    Like :func:`_check_readable`, this keeps the library's own lines about a bad file from
    reaching the user before dbench's one line; the yielded list gets the captured lines, for
    that line to quote. When the block ends without an error the text is passed on to where it
    was going, so nothing a successful read says is lost.
    """
    lines: list[str] = []
    streams = sys.stdout, sys.stderr
    for stream in streams:
        try:
            stream.flush()  # Python's own text goes out before the descriptors are swapped
        except (AttributeError, OSError, ValueError):
            pass
    _flush_c_stdio()
    saved: dict[int, tuple[int, Any]] = {}
    texts = io.StringIO(), io.StringIO()
    ok = False
    try:
        for fd in (1, 2):
            try:
                old = os.dup(fd)
            except OSError:
                continue  # started with that descriptor closed: nothing to keep from it
            saved[fd] = (old, tempfile.TemporaryFile())
            os.dup2(saved[fd][1].fileno(), fd)
        sys.stdout, sys.stderr = texts
        yield lines
        ok = True
    finally:
        sys.stdout, sys.stderr = streams
        _flush_c_stdio()
        for fd, (old, tmp) in saved.items():
            os.dup2(old, fd)
            os.close(old)
            tmp.seek(0)
            text = tmp.read()
            tmp.close()
            if ok and text:
                os.write(fd, text)
            lines += text.decode("utf-8", "replace").splitlines()
        for stream, text in zip(streams, texts):
            if ok and text.getvalue() and stream is not None:
                stream.write(text.getvalue())
            lines += text.getvalue().splitlines()


def _unreadable(path: Path, exc: Exception, said: list[str]) -> DbenchInputError:
    """One error for an EXR file OpenEXR could not read, quoting the library's own account
    (``said``, captured by :func:`_library_output`; its line begins with the path, named once
    here) where it gave one, else the binding's exception."""
    own = [ln.split(": ", 1)[-1] if ln.startswith(str(path)) else ln
           for ln in said if "EXR_ERR" in ln]
    return DbenchInputError(f"{path}: not a readable EXR file (truncated or damaged: "
                            f"{own[0] if own else exc})")


def exr_header(path: str | os.PathLike) -> tuple[tuple[int, int], list[str], Window]:
    """((H, W), raw channel names, data window) of an EXR file, reading no pixels. The pixels
    read are the data window's only, so two files of one size but other windows would be
    compared offset: :func:`dbench.datasets.folders.load.scan_folder` needs one window per
    view (docs/formats.md §1)."""
    import OpenEXR

    path = Path(path)
    _check_readable(path)
    said: list[str] = []
    try:
        with _library_output() as said, OpenEXR.File(str(path), header_only=True) as f:
            if len(f.parts) != 1:
                raise DbenchInputError(f"{path}: multi-part EXR ({len(f.parts)} parts); "
                                       "expected a single-part file")
            header = f.header()
            lo, hi = header["dataWindow"]
            names = [c.name for c in header["channels"]]
            bad = [c.name for c in header["channels"] if (c.xSampling, c.ySampling) != (1, 1)]
    except DbenchInputError:
        raise
    except Exception as exc:  # noqa: BLE001 - the binding raises RuntimeError, KeyError, ...
        raise _unreadable(path, exc, said) from None
    if bad:
        raise DbenchInputError(f"{path}: subsampled channels {bad}; expected full resolution")
    window = ((int(lo[0]), int(lo[1])), (int(hi[0]), int(hi[1])))
    return (int(hi[1] - lo[1] + 1), int(hi[0] - lo[0] + 1)), names, window


def read_channels(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Every channel of an EXR file by raw name, as (H, W) float32 (half floats widened)."""
    import OpenEXR

    path = Path(path)
    _check_readable(path)
    said: list[str] = []
    try:
        # a file cut short passes the header read and fails here, the library printing its
        # own lines first (_library_output keeps them for the one line said)
        with _library_output() as said, OpenEXR.File(str(path), separate_channels=True) as f:
            return {k: np.asarray(v.pixels, dtype=np.float32) for k, v in f.channels().items()}
    except Exception as exc:  # noqa: BLE001
        raise _unreadable(path, exc, said) from None


def write_channels(path: str | os.PathLike, channels: dict[str, np.ndarray]) -> None:
    """Write (H, W) float32 channels under their raw names (ZIP, lossless), atomically."""
    import OpenEXR

    data = {k: np.ascontiguousarray(v, dtype=np.float32) for k, v in channels.items()}
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with atomic_path(path, suffix=".tmp.exr") as tmp:
        with OpenEXR.File(header, data) as f:
            f.write(str(tmp))


def split_name(name: str) -> tuple[str, str]:
    """(layer, component) of a raw channel name, both lower case (module docstring)."""
    if "." in name:
        layer, comp = name.rsplit(".", 1)
        return layer.lower(), comp.lower()
    m = _PBRT.fullmatch(name)
    if m:
        return m.group(1).lower(), m.group(2).lower()
    if name.upper() in ("R", "G", "B", "A", "Y", "Z"):
        return "", name.lower()
    return name.lower(), ""


def _groups(path: Path, names: list[str]) -> dict[str, dict[str, str]]:
    """{layer: {component: raw name}}; two raw names read as one component are an error."""
    groups: dict[str, dict[str, str]] = {}
    for name in names:
        layer, comp = split_name(name)
        other = groups.setdefault(layer, {}).get(comp)
        if other is not None:
            raise DbenchInputError(f"{path}: channels {other!r} and {name!r} both read as "
                                   f"layer {layer!r} component {comp!r}; expected one")
        groups[layer][comp] = name
    return groups


def _pick(comps: dict[str, str], count: int) -> tuple[str, ...] | None:
    """Raw channel names giving ``count`` components in order, or None."""
    if count == 1 and len(comps) == 1:
        return tuple(comps.values())
    for want in COMPONENTS[count]:
        if all(c in comps for c in want):
            return tuple(comps[c] for c in want)
    return None


def _describe(comps: dict[str, str]) -> str:
    return ", ".join(sorted(comps.values()))


def layer_for_tag(path: Path, names: list[str], buffer: str) -> Layer:
    """The layer of a one-feature file (``.alb.exr`` …) that holds ``buffer``.

    A layer aliased to ``buffer`` wins; otherwise the single layer with the right channel
    count is taken. Several candidates or none are DbenchInputErrors naming the file.
    """
    count = CHANNELS[buffer]
    groups = _groups(path, names)
    named = [g for g in groups if ALIASES.get(g, ("", 0))[0] == buffer
             or (g == "" and buffer == "color")]
    found = [(g, _pick(groups[g], count)) for g in (named or groups)]
    found = [(g, chans) for g, chans in found if chans is not None]
    if len(found) == 1:
        return Layer(path, buffer, found[0][1])
    sets = " or ".join(",".join(c.upper() for c in s) for s in COMPONENTS[count])
    if not found:
        raise DbenchInputError(
            f"{path}: {buffer} needs {count} channel{'s' if count > 1 else ''} ({sets}"
            f"{' or any single channel' if count == 1 else ''}); found channels "
            f"{', '.join(sorted(names)) or 'none'}")
    raise DbenchInputError(f"{path}: several layers could hold {buffer} "
                           f"({', '.join(repr(g) for g, _ in found)}); expected one")


def layers_of(path: Path, names: list[str]) -> tuple[dict[str, Layer], list[str]]:
    """Buffers of a multi-layer file through the alias table, and the raw channels left unused.

    Two layers giving one buffer with equal priority are an error naming both; a recognised
    layer with the wrong channels is an error listing what it has.
    """
    found: dict[str, Layer] = {}
    unused: list[str] = []
    for layer, comps in _groups(path, names).items():
        if layer == "":
            # Bare channels: R,G,B (+A) are the colour (Mitsuba, pbrt), a bare Z is depth.
            rgb = _pick({c: n for c, n in comps.items() if c in ("r", "g", "b")}, 3)
            candidates = [("color", rgb, 1)] if rgb else []
            if "z" in comps:
                candidates.append(("depth", (comps["z"],), 1))
            used = {n for _, chans, _ in candidates for n in chans}
            unused += [n for n in comps.values() if n not in used]
        else:
            buffer, prio = ALIASES.get(layer, (None, 0))
            if buffer is None and set(comps) == {"t"}:
                buffer, prio = "depth", 1  # Mitsuba's aov depth type, whatever its name
            if buffer is None:
                unused += comps.values()
                continue
            chans = _pick(comps, CHANNELS[buffer])
            if chans is None:
                raise DbenchInputError(
                    f"{path}: layer {layer!r} ({_describe(comps)}) does not give the "
                    f"{CHANNELS[buffer]} channel(s) {buffer} needs")
            candidates = [(buffer, chans, prio)]
        for buffer, chans, prio in candidates:
            old = found.get(buffer)
            if old is not None and old.priority == prio:
                raise DbenchInputError(f"{path}: channels {', '.join(old.channels)} and "
                                       f"{', '.join(chans)} both give {buffer}; expected one")
            if old is None or prio > old.priority:
                if old is not None:
                    unused += old.channels
                found[buffer] = Layer(path, buffer, chans, prio)
            else:
                unused += chans
    return found, sorted(unused)


def stack(channels: dict[str, np.ndarray], layer: Layer) -> np.ndarray:
    """(H, W, C) float32 of ``layer`` from a :func:`read_channels` result."""
    return np.stack([channels[c] for c in layer.channels], axis=-1)


def detect_normal_encoding(normal: np.ndarray) -> str:
    """``"unsigned"`` when (H, W, 3) normals look stored as n·0.5 + 0.5, else ``"signed"``
    (also when undecided): :func:`dbench.datasets.folders.normals.decide`, whose texts and warning
    the folder loader records."""
    from .normals import decide

    return decide(normal, "normal image").encoding


def decode_normals(normal: np.ndarray, encoding: str) -> np.ndarray:
    """Normals in [-1, 1]: 2n − 1 for ``"unsigned"`` except on all-zero pixels (nothing hit,
    kept 0 as in dbench's own buffers); unchanged for ``"signed"``."""
    if encoding != "unsigned":
        return normal
    hit = np.any(normal != 0, axis=-1, keepdims=True)
    return np.where(hit, 2.0 * normal - 1.0, 0.0).astype(np.float32)


class Reader:
    """Reads each EXR file once per load (dbench.datasets.folders.load) and checks what every
    buffer must satisfy: called with a :class:`Layer`, gives its (H, W, C) float32 buffer;
    ``layers``: what was read, in order (``meta["layers_read"]``, :func:`layers_report`)."""

    def __init__(self) -> None:
        self.cache: dict[Path, dict[str, np.ndarray]] = {}
        self.layers: list[Layer] = []

    def __call__(self, layer: Layer) -> np.ndarray:
        if layer.file not in self.cache:
            self.cache[layer.file] = read_channels(layer.file)
        if layer not in self.layers:
            self.layers.append(layer)  # meta["layers_read"]
        arr = stack(self.cache[layer.file], layer)
        # Motion is NaN wherever there is no previous position, everywhere on a first frame.
        if layer.buffer != "motion" and np.isnan(arr).all():
            raise DbenchInputError(f"{layer.file}: {layer.buffer} is NaN everywhere; expected "
                                   "an image")
        if layer.buffer == "emitter" and not (np.nanmin(arr) >= 0 and np.nanmax(arr) <= 1):
            raise DbenchInputError(f"{layer.file}: emitter values in [{np.nanmin(arr)}, "
                                   f"{np.nanmax(arr)}]; expected coverage in [0, 1]")
        return arr


def refuse_non_finite(arr: np.ndarray, path: Path, what: str) -> np.ndarray:
    """``arr`` ((H, W, C) colour read from ``path``), refused naming the file, the first pixel
    (x, y) that is not finite and the count of such values, when it holds NaN or ±Inf: every
    method would be blamed for values its input already had, and the scores would compare
    nothing there (docs/formats.md §1: colour is linear HDR radiance)."""
    bad = ~np.isfinite(arr)
    if bad.any():
        y, x = (int(i) for i in np.argwhere(bad)[0][:2])
        raise DbenchInputError(f"{path}: {what} contains NaN or Inf: {int(bad.sum())} values, "
                               f"the first at pixel (x, y) = ({x}, {y}); expected finite values")
    return arr


def layers_report(read: list[Layer], folder: Path, ignored_files: tuple[str, ...] = ()
                  ) -> dict[str, list[str]]:
    """``meta["layers_read"]`` and ``meta["layers_ignored"]``: one line per file and buffer read
    (``"v_0004.exr: albedo (albedo.R, albedo.G, albedo.B)"``), and per file read the raw
    channels no buffer took (``"v_0004.exr: A, _arg_0.R, _arg_0.G, _arg_0.B"``), plus the
    view's files left unread (``ldr``, ``sh1x/y/z`` and unknown EXR files)."""
    lines, used, files = [], {}, []
    for layer in read:
        lines.append(f"{layer.file.name}: {layer.buffer} ({', '.join(layer.channels)})")
        if layer.file not in used:
            files.append(layer.file)
        used.setdefault(layer.file, set()).update(layer.channels)
    ignored = []
    for path in files:
        left = [c for c in exr_header(path)[1] if c not in used[path]]
        if left:
            ignored.append(f"{path.name}: {', '.join(sorted(left))}")
    ignored += [f"{name}: whole file (not a buffer dbench reads)" for name in ignored_files
                if (Path(folder) / name).exists()]
    return {"layers_read": lines, "layers_ignored": ignored}
