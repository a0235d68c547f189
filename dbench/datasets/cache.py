"""Content-addressed cache of rendered buffers.

An entry is a folder ``<root>/<kind>/<key>/`` holding ``buffers.exr`` (float32 images with
named channels), optionally its arrays (float64 statistics, which EXR cannot hold: a folder
``arrays/`` of ``.npy`` files, :mod:`.array_files`, or, compressed, ``arrays.npz``), and
``meta.json``. The key is a hash of everything that changes the pixels: the scene dictionary
itself (canonicalised, so editing a scene invalidates its entries, with the bytes of every
file it names by ``"filename"``: :mod:`.file_refs`), resolution, spp, seed (for
references: the reference seed ``ref_seed``, not the noisy seed, so noisy renders of several
seeds share one reference entry), integrator settings, transform, the Mitsuba / Dr.Jit /
mitransient versions and variant, and version markers of what an entry holds (``emitter`` in
feature entries, which hold albedo, normal, depth, position and emitter; ``var`` in reference
entries, which hold ``reference`` and ``reference_var``; ``nonfinite`` in noisy, statistics
and reference entries, whose NaN or ±Inf samples count as 0 and are counted in their meta,
:mod:`.nonfinite`), so entries written before a buffer or a rule existed are not reused.

An entry is built in a temporary folder and renamed into place when complete; ``meta.json`` is
written last. A killed render leaves only a ``.tmp-*`` folder, which readers ignore and
:func:`Cache.clean` removes (a cache removes such folders older than a day by itself).

Integrity: ``meta.json`` records the canonical description the entry was built from and the
size and checksum of each of its files (xxh3-128, :mod:`.checksums`; sha256 in entries before
format 5, which are checked with it). :meth:`Cache.get` checks both (a cheap read of files that
are about to be read anyway; the files in ``arrays/`` are read and checked in the same pass,
and the entry it returns holds them); an entry whose description differs (a folder copied
under another key), whose files are missing, truncated or replaced, or whose ``meta.json`` is
unreadable is a miss: one warning line names it, the caller renders again, and
:meth:`Cache.put` replaces the damaged folder atomically. An entry whose ``meta.json``
records no checksums (written before they existed) is a miss too, rendered again and
replaced: that its files load says nothing about whether they are the pixels its key stands
for (another scene's ``buffers.exr`` copied in loads just as well), and adopting it would seal
whatever it holds with a checksum.

A cache that cannot be written (a full disk, a read-only or unwritable folder, the root
that cannot be created) only costs time: :meth:`Cache.put` then leaves no partial entry,
prints one warning line per process naming the folder and the system's reason, stores nothing
more in that folder for the rest of the process, and returns an entry holding the buffers in
memory, so the run carries on with the renders it has (README.md, "How renders work").

Mostly empty transient videos are stored by their non-zero rows (:mod:`.sparse_rows`,
docs/transient.md §6), uncompressed arrays as an ``arrays/`` folder (format 4 on), compressed
ones as an ``arrays.npz``. Entries are written in format 5 (format 4's layouts, xxh3-128
checksums); entries of formats 1 to 4 (an ``arrays.npz``, packed from format 2 on; ``arrays/``
in 4) read as before.

Location: ``--cache DIR`` or ``DBENCH_CACHE``, default ``~/.cache/dbench``.
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import sys
import time
import uuid
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from .. import io
from ..errors import OutputError
from ..memory import small_pages
from . import array_files, checksums, sparse_rows
from .checksums import DigestingWriter, NoDigest, file_record
from .file_refs import file_ref

#: The first entry format: images and dense arrays (``arrays.npz``), sha256 checksums. Entries
#: of formats 1-4 were written by earlier versions and are still read.
CACHE_FORMAT = 1
#: The format of an entry whose arrays.npz holds packed rows (:mod:`.sparse_rows`), integer
#: arrays among them narrowed: code that reads only earlier formats takes such an entry for a
#: miss instead of misreading it.
PACKED_FORMAT = 3
#: The format of an entry whose uncompressed arrays are a folder of ``.npy`` files
#: (:mod:`.array_files`), packed as in :data:`PACKED_FORMAT` where asked.
FILES_FORMAT = 4
#: The format of every entry written now: any of the layouts above (told apart by the files
#: an entry holds), its files' checksums xxh3-128 where earlier formats have sha256
#: (:mod:`.checksums`).
CHECKSUM_FORMAT = checksums.FIRST_FORMAT
#: Entry formats this code reads: 2 is packed rows without narrowed integers.
FORMATS = (CACHE_FORMAT, 2, PACKED_FORMAT, FILES_FORMAT, CHECKSUM_FORMAT)


def default_root() -> Path:
    return Path(os.environ.get("DBENCH_CACHE", Path.home() / ".cache" / "dbench"))


def origin(root: str | os.PathLike | None) -> str:
    """What named the folder of ``Cache(root)``, for a refusal to name: ``--cache`` (given),
    else ``$DBENCH_CACHE`` (set), else "the cache folder" (:func:`default_root`)."""
    if root is not None:
        return "--cache"
    return "$DBENCH_CACHE" if os.environ.get("DBENCH_CACHE") else "the cache folder"


def canonical(obj: Any, files: set | None = None) -> Any:
    """A JSON-able, deterministic description of a scene dictionary (Mitsuba objects included).
    ``files``, where given, gathers the (name, sha256 or None) of each ``"filename"`` string
    met on the way (:func:`referenced`)."""
    if isinstance(obj, dict):
        # a "filename" string stands for the bytes Mitsuba reads for it: an edited texture or
        # mesh is another scene (dbench.datasets.file_refs)
        out = {}
        for k, v in sorted(obj.items(), key=lambda kv: str(kv[0])):
            if k == "filename" and isinstance(v, str):
                out[str(k)] = ref = file_ref(v)
                if files is not None:
                    files.add((ref["file"], ref["sha256"]))
            else:
                out[str(k)] = canonical(v, files)
        return out
    if isinstance(obj, (list, tuple)):
        return [canonical(v, files) for v in obj]
    if isinstance(obj, (bool, int, str)) or obj is None:
        return obj
    if isinstance(obj, float):
        return repr(obj)
    if isinstance(obj, np.ndarray):
        return {"ndarray": hashlib.sha1(np.ascontiguousarray(obj).tobytes()).hexdigest(),
                "shape": list(obj.shape)}
    type_name = type(obj).__name__
    if "Bitmap" in type_name:
        return {"bitmap": canonical(np.array(obj))}
    if "VolumeGrid" in type_name:  # its repr names the size, not the voxels
        return {"volume_grid": canonical(np.array(obj)), "channels": int(obj.channel_count())}
    if hasattr(obj, "faces_buffer") and hasattr(obj, "vertex_positions_buffer"):
        # a mesh built in memory: its repr names the counts, not the vertices, and its media's
        # repr leaves out their phase functions
        media = [None if m is None else {"medium": repr(m), "phase": repr(m.phase_function())}
                 for m in (obj.interior_medium(), obj.exterior_medium())]
        out = {"mesh": canonical(np.array(obj.vertex_positions_buffer())),
               "faces": canonical(np.array(obj.faces_buffer())), "media": media,
               "repr": repr(obj)}
        # a mesh a build loaded from a file (a ply) brings UVs, normals and a BSDF whose
        # textures its repr does not show (entries added only where there are some)
        if obj.has_vertex_texcoords():
            out["uv"] = canonical(np.array(obj.vertex_texcoords_buffer()))
        if obj.has_vertex_normals():
            out["normals"] = canonical(np.array(obj.vertex_normals_buffer()))
        bsdf = _parameters(obj.bsdf()) if obj.bsdf() is not None else {}
        if bsdf:
            out["bsdf"] = bsdf
        return _loaded(out, type_name, files)
    if hasattr(obj, "matrix"):
        return {type_name: canonical(np.array(obj.matrix, dtype=np.float64))}
    if hasattr(obj, "class_name"):  # another loaded Mitsuba object: a texture, a BSDF, ...
        return _loaded({type_name: repr(obj), "params": _parameters(obj)}, type_name, files)
    return {type_name: repr(obj)}


def _loaded(out: dict, type_name: str, files: set | None) -> dict:
    """``out``, the description of a loaded object, counted in ``files`` (:func:`referenced`):
    what it read from files is in it, not in a "filename" string."""
    if files is not None:
        digest = hashlib.sha256(json.dumps(out, sort_keys=True).encode()).hexdigest()
        files.add((f"<loaded {type_name} {digest[:12]}>", digest))
    return out


def _parameters(obj: Any) -> dict:
    """Every parameter ``mi.traverse`` exposes of a loaded Mitsuba object (a texture's pixels, a
    BSDF's values and those of the textures it holds), described by :func:`canonical`: its repr
    names a bitmap's size and mean, not its pixels, so a texture loaded in a Python scene's
    build would otherwise key an edited file as the old one."""
    from .mitsuba_env import mitsuba

    params = mitsuba().traverse(obj)
    out = {}
    for key in sorted(params.keys()):
        value = params[key]
        if not hasattr(value, "matrix"):  # (transforms: canonical reads their matrix)
            array = np.asarray(value)
            value = array if array.dtype != object else repr(value)
        out[key] = canonical(value)
    return out


def referenced(d) -> tuple:
    """((name, sha256 or None), ...) of every ``"filename"`` string in the (nested) dictionary
    ``d``, and of every loaded Mitsuba object in it (``<loaded Type digest>``, the sha256 of its
    parameters: a texture a build loaded from a file), sorted and without repeats: the content
    a scene built from ``d`` reads, found by :func:`canonical`'s own walk."""
    found: set = set()
    canonical(d, found)
    return tuple(sorted(found, key=lambda t: (t[0], t[1] or "")))


def make_key(description: dict) -> str:
    text = json.dumps(canonical(description), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:24]


@dataclass
class Entry:
    """A cache entry: its folder and ``meta.json``. An entry :meth:`Cache.put` did not store
    (a disabled or unwritable cache) holds its buffers in memory instead (``held_images``,
    ``held_arrays``, as they were given) and reads them from there."""

    path: Path
    meta: dict
    held_images: dict[str, np.ndarray] | None = None
    held_arrays: dict[str, np.ndarray] | None = None

    @small_pages()  # what it reads is fresh arrays (dbench/memory.py)
    def images(self) -> dict[str, np.ndarray]:
        if self.held_images is not None:
            return dict(self.held_images)
        f = self.path / "buffers.exr"
        return io.read_exr(f) if f.exists() else {}

    def arrays(self) -> dict[str, np.ndarray]:
        if self.held_arrays is not None:  # (those Cache.get read and checked)
            return dict(self.held_arrays)
        return self._read_arrays()

    @small_pages()
    def _read_arrays(self) -> dict[str, np.ndarray]:
        folder = self.path / array_files.FOLDER
        if folder.is_dir():  # (an entry :meth:`Cache.put` returns: its files were just written)
            return array_files.read(folder, _array_files(self.path), NoDigest)[0]
        f = self.path / "arrays.npz"
        if not f.exists():
            return {}
        with np.load(f) as z:
            return sparse_rows.unpack({k: z[k] for k in z.files})


def _array_files(path: Path) -> list[str]:
    """The names of the files in the entry ``path``'s ``arrays/`` folder."""
    return sorted(p.name for p in (path / array_files.FOLDER).iterdir())


#: Files an entry may hold besides meta.json (and the files of ``arrays/``).
DATA_FILES = ("buffers.exr", "arrays.npz")
#: Why :func:`verify` refuses an entry whose meta.json records no checksums.
UNCHECKED = "no file checksums, so its contents cannot be checked"
#: Leftover temporary folders older than this are removed (seconds).
STALE_TMP_S = 24 * 3600
#: {cache folder: the system's reason} of the folders this process found it cannot write:
#: warned about once, and not written to again (a full disk stays full for a run's length)
_UNWRITABLE: dict[str, str] = {}


def verify(path: Path, meta: dict, description: dict, hash_arrays: bool = True) -> str:
    """'' when the entry at ``path`` is intact and was built from ``description``, else why.
    ``hash_arrays=False`` checks the files of ``arrays/`` by their size only: the caller reads
    them with their checksum (:func:`read_arrays`)."""
    if meta.get("description") != json.loads(json.dumps(canonical(description))):
        return "built from another description"
    files = meta.get("files")
    if not isinstance(files, dict):
        return UNCHECKED
    present = [n for n in DATA_FILES if (path / n).exists()]
    if (path / array_files.FOLDER).is_dir():
        present += [f"{array_files.FOLDER}/{n}" for n in _array_files(path)]
    for name in present:  # a file the checksums leave out would be read unchecked
        if name not in files:
            return f"{name} has no checksum"
    algorithm = checksums.algorithm(meta)
    for name, record in files.items():
        if not isinstance(record, dict):
            return f"checksum of {name} unreadable"
        f = path / name
        if not f.is_file():
            return f"{name} missing"
        if f.stat().st_size != record.get("size"):
            return f"{name} has {f.stat().st_size} bytes, expected {record.get('size')}"
        if (hash_arrays or not name.startswith(array_files.FOLDER + "/")) and \
                file_record(f, algorithm) != record:
            return f"{name} checksum differs"
    return ""


@small_pages()  # what it reads is fresh arrays (dbench/memory.py)
def read_arrays(path: Path, meta: dict) -> tuple[dict[str, np.ndarray] | None, str]:
    """(the arrays of the entry at ``path``, '') read from its ``arrays/`` folder with each
    file's checksum taken in the same pass, or (None, why) when one differs from ``meta``'s
    or a file is damaged (after :func:`verify` with ``hash_arrays=False``)."""
    prefix = array_files.FOLDER + "/"
    try:
        arrays, records = array_files.read(path / array_files.FOLDER, _array_files(path),
                                           partial(checksums.Digest, checksums.algorithm(meta)))
    except (OSError, ValueError) as exc:
        return None, str(exc)
    for name, record in records.items():
        if record != meta["files"].get(prefix + name):
            return None, f"{prefix}{name} checksum differs"
    return arrays, ""


class Cache:
    """Get and put rendered buffers by content key."""

    def __init__(self, root: str | os.PathLike | None = None, enabled: bool = True):
        self.root = Path(root) if root is not None else default_root()
        self.enabled = enabled
        self._cleaned = False

    def _dir(self, kind: str, key: str) -> Path:
        return self.root / kind / key

    def _warn(self, kind: str, key: str, why: str) -> None:
        state = "cannot be trusted" if why == UNCHECKED else "is damaged"
        print(f"dbench: cache entry {kind}/{key} {state} ({why}); rendering it again",
              file=sys.stderr)

    def get(self, kind: str, description: dict) -> Entry | None:
        """The intact entry for ``description``, or None (a miss; damaged entries warn)."""
        if not self.enabled:
            return None
        key = make_key(description)
        path = self._dir(kind, key)
        if not path.exists():
            return None
        meta_file = path / "meta.json"
        try:
            meta = io.read_json(meta_file)
            if not isinstance(meta, dict):
                raise ValueError("meta.json is not an object")
        except (OSError, ValueError) as exc:
            self._warn(kind, key, f"meta.json unreadable: {type(exc).__name__}")
            return None
        if meta.get("cache_format") not in FORMATS:
            return None
        why = verify(path, meta, description, hash_arrays=False)
        arrays = None
        if not why and (path / array_files.FOLDER).is_dir():
            arrays, why = read_arrays(path, meta)
        if why:
            self._warn(kind, key, why)
            return None
        return Entry(path, meta, held_arrays=arrays)

    def put(self, kind: str, description: dict, images: dict[str, np.ndarray] | None = None,
            arrays: dict[str, np.ndarray] | None = None, meta: dict | None = None,
            compress: bool = False, sparse: tuple[str, ...] = (),
            rows: np.ndarray | None = None, compress_images: bool = True,
            raw_images: tuple[str, ...] = (), kept: dict[str, np.ndarray] | None = None
            ) -> Entry:
        """Store an entry atomically. The arrays are written uncompressed, one ``.npy`` file
        each in ``arrays/`` (:mod:`.array_files`): float64 statistics deflate to about 2/3 of
        their size at 15-25× the write time, and float32 transient references to 93 % at 25×
        (README.md, "How renders work"); ``compress=True`` writes them deflated into
        ``arrays.npz``. ``sparse`` names arrays
        that share every axis but the last and are stored by their non-zero rows
        (:mod:`.sparse_rows`; :meth:`Entry.arrays` gives them back bit for bit); ``rows``, where
        the caller found them, are those rows (bool, the arrays' shape but the last axis;
        :func:`.sparse_rows.layout`), and every row it leaves out must be zero; ``kept``,
        where the caller gathered them, those rows of some of the ``sparse`` arrays
        ({name: (kept rows, channels)}, in order: the transient collector's, from the device).
        ``compress_images=False`` writes ``buffers.exr`` uncompressed, and ``raw_images`` names
        images written uncompressed in a part of their own beside the others
        (:func:`dbench.io.write_exr`: a sequence frame's noisy colour beside its G-buffer).

        A folder that cannot be written (OSError, or the OutputError :mod:`dbench.io` makes of
        it) is not an error: one warning line per process, nothing left behind, and the entry
        returned holds the buffers in memory (module docstring)."""
        key = make_key(description)
        final = self._dir(kind, key)
        meta = {**(meta or {}), "cache_format": CHECKSUM_FORMAT,
                "kind": kind, "key": key, "description": canonical(description),
                "created": time.time()}
        held = Entry(final, meta, dict(images or {}), dict(arrays or {}))
        if not self.enabled or str(self.root) in _UNWRITABLE:
            return held
        tmp = final.parent / f".tmp-{key}-{uuid.uuid4().hex[:8]}"
        try:
            final.parent.mkdir(parents=True, exist_ok=True)
            if not self._cleaned:
                self._cleaned = True
                self.clean(older_than_s=STALE_TMP_S)
            tmp.mkdir()
            self._write(tmp, final, description, meta, images, arrays, compress, sparse,
                        (rows, kept), {"compress": compress_images, "raw": tuple(raw_images)})
        except (OSError, OutputError) as exc:
            # the renders are in memory and right; only the time a later hit would save is lost
            self._unwritable(exc)
            meta.pop("files", None)  # of files that were not kept
            return held
        finally:
            if tmp.exists():
                shutil.rmtree(tmp, ignore_errors=True)
        return Entry(final, meta)

    def _unwritable(self, exc: OSError | OutputError) -> None:
        """Note that this process cannot write the cache folder; one warning line the first
        time."""
        root = str(self.root)
        if root in _UNWRITABLE:
            return
        reason = exc.reason if isinstance(exc, OutputError) else (exc.strerror or str(exc))
        _UNWRITABLE[root] = reason
        print(f"dbench: cache at {root} is not writable ({reason}); carrying on without "
              f"storing renders", file=sys.stderr)

    def _write(self, tmp: Path, final: Path, description: dict, meta: dict,
               images: dict[str, np.ndarray] | None, arrays: dict[str, np.ndarray] | None,
               compress: bool, sparse: tuple[str, ...], kept_rows: tuple, exr: dict) -> None:
        """Fill the temporary folder ``tmp`` and rename it to ``final`` (:meth:`put`);
        ``kept_rows``: :meth:`put`'s (``rows``, ``kept``); ``exr``:
        :func:`dbench.io.write_exr`'s options."""
        key = meta["key"]
        rows, kept = kept_rows
        if images:
            io.write_exr(tmp / "buffers.exr", images, **exr)
        records = {}
        if arrays and not compress:
            records = {f"{array_files.FOLDER}/{n}": r for n, r in array_files.write(
                tmp / array_files.FOLDER, arrays, sparse, DigestingWriter, rows, kept).items()}
        elif arrays:
            with io.atomic_path(tmp / "arrays.npz", suffix=".tmp.npz") as t:
                with open(t, "wb") as fh:
                    writer = DigestingWriter(fh)
                    sparse_rows.save(writer, arrays, sparse, compress=compress, keep=rows,
                                     kept=kept)
            records["arrays.npz"] = writer.record()
        meta["files"] = {**records, **{n: records.get(n) or file_record(tmp / n)
                                       for n in DATA_FILES if (tmp / n).is_file()}}
        io.write_json(tmp / "meta.json", meta)
        try:
            os.rename(tmp, final)
        except OSError:
            if self._intact(final, description):
                pass  # another process finished the same entry first (same content)
            else:  # a damaged entry: move it aside, then put the new one in its place
                trash = final.parent / f".tmp-{key}-old-{uuid.uuid4().hex[:8]}"
                os.rename(final, trash)
                os.rename(tmp, final)
                shutil.rmtree(trash, ignore_errors=True)

    @staticmethod
    def _intact(path: Path, description: dict) -> bool:
        try:
            meta = io.read_json(path / "meta.json")
        except (OSError, ValueError):
            return False
        return isinstance(meta, dict) and meta.get("cache_format") in FORMATS and \
            "files" in meta and not verify(path, meta, description)

    def clean(self, older_than_s: float = 0.0) -> int:
        """Remove leftovers of interrupted writes (only those older than ``older_than_s``
        seconds, so a write in progress elsewhere is left alone); return how many."""
        removed = 0
        if not self.root.exists():
            return 0
        now = time.time()
        for leftover in self.root.glob("*/.tmp-*"):
            try:
                if older_than_s and now - leftover.stat().st_mtime < older_than_s:
                    continue
            except OSError:
                continue
            shutil.rmtree(leftover, ignore_errors=True)
            removed += 1
        return removed
