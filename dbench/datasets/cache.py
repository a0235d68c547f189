"""Content-addressed cache of rendered buffers.

An entry is a folder ``<root>/<kind>/<key>/`` holding ``buffers.exr`` (float32 images with
named channels), optionally ``arrays.npz`` (float64 statistics, which EXR cannot hold), and
``meta.json``. The key is a hash of everything that changes the pixels: the scene dictionary
itself (canonicalised, so editing a scene invalidates its entries), resolution, spp, seed,
integrator settings, transform and the Mitsuba / Dr.Jit / mitransient versions and variant.

An entry is built in a temporary folder and renamed into place when complete; ``meta.json`` is
written last. A killed render leaves only a ``.tmp-*`` folder, which readers ignore and
:func:`Cache.clean` removes.

Location: ``--cache DIR`` or ``DBENCH_CACHE``, default ``~/.cache/dbench``.
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import time
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .. import io

CACHE_FORMAT = 1


def default_root() -> Path:
    return Path(os.environ.get("DBENCH_CACHE", Path.home() / ".cache" / "dbench"))


def canonical(obj: Any) -> Any:
    """A JSON-able, deterministic description of a scene dictionary (Mitsuba objects included)."""
    if isinstance(obj, dict):
        return {str(k): canonical(v) for k, v in sorted(obj.items(), key=lambda kv: str(kv[0]))}
    if isinstance(obj, (list, tuple)):
        return [canonical(v) for v in obj]
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
    if hasattr(obj, "matrix"):
        return {type_name: canonical(np.array(obj.matrix, dtype=np.float64))}
    return {type_name: repr(obj)}


def make_key(description: dict) -> str:
    text = json.dumps(canonical(description), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:24]


@dataclass
class Entry:
    path: Path
    meta: dict

    def images(self) -> dict[str, np.ndarray]:
        f = self.path / "buffers.exr"
        return io.read_exr(f) if f.exists() else {}

    def arrays(self) -> dict[str, np.ndarray]:
        f = self.path / "arrays.npz"
        if not f.exists():
            return {}
        with np.load(f) as z:
            return {k: z[k] for k in z.files}


class Cache:
    """Get and put rendered buffers by content key."""

    def __init__(self, root: str | os.PathLike | None = None, enabled: bool = True):
        self.root = Path(root) if root is not None else default_root()
        self.enabled = enabled

    def _dir(self, kind: str, key: str) -> Path:
        return self.root / kind / key

    def get(self, kind: str, description: dict) -> Entry | None:
        if not self.enabled:
            return None
        path = self._dir(kind, make_key(description))
        meta_file = path / "meta.json"
        if not meta_file.exists():
            return None
        try:
            meta = io.read_json(meta_file)
        except (OSError, ValueError):
            return None
        if meta.get("cache_format") != CACHE_FORMAT:
            return None
        return Entry(path, meta)

    def put(self, kind: str, description: dict, images: dict[str, np.ndarray] | None = None,
            arrays: dict[str, np.ndarray] | None = None, meta: dict | None = None) -> Entry:
        key = make_key(description)
        final = self._dir(kind, key)
        meta = {**(meta or {}), "cache_format": CACHE_FORMAT, "kind": kind, "key": key,
                "description": canonical(description), "created": time.time()}
        if not self.enabled:
            return Entry(final, meta)
        final.parent.mkdir(parents=True, exist_ok=True)
        tmp = final.parent / f".tmp-{key}-{uuid.uuid4().hex[:8]}"
        tmp.mkdir()
        try:
            if images:
                io.write_exr(tmp / "buffers.exr", images)
            if arrays:
                with io.atomic_path(tmp / "arrays.npz", suffix=".tmp.npz") as t:
                    with open(t, "wb") as fh:
                        np.savez_compressed(fh, **arrays)
            io.write_json(tmp / "meta.json", meta)
            try:
                os.rename(tmp, final)
            except OSError:
                # Another process finished the same entry first; identical content by key.
                if not (final / "meta.json").exists():
                    raise
        finally:
            if tmp.exists():
                shutil.rmtree(tmp, ignore_errors=True)
        return Entry(final, meta)

    def clean(self) -> int:
        """Remove leftovers of interrupted writes; return how many were removed."""
        removed = 0
        if not self.root.exists():
            return 0
        for leftover in self.root.glob("*/.tmp-*"):
            shutil.rmtree(leftover, ignore_errors=True)
            removed += 1
        return removed
