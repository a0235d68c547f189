"""The bytes behind a scene dictionary's ``"filename"`` strings, for cache keys and fingerprints.

A scene dictionary (a Python scene file's ``build()``, a plugin scene, a sequence frame, a
transient scene) names textures, meshes, environment maps, volumes and measured BSDFs by
``"filename"``; ``mi.load_dict`` reads those files when it builds the objects. A key made of
the dictionary alone would keep serving renders of a texture after it was edited, so
:func:`dbench.datasets.cache.canonical` describes each such string by the name as written and
the sha256 of the file Mitsuba opens for it (README.md, "Your scene, your renders, any size";
Mitsuba XML files are hashed by :mod:`dbench.datasets.scene_files.assets`, which follows the
XML parser's own look-ups).

The file is found as ``mi.load_dict`` finds it: Mitsuba's process-wide ``FileResolver`` (the
working directory Mitsuba started in, and any folder a caller prepended) returns the first
folder holding the name, else the name unchanged, which is opened relative to the working
directory; absolute names are used as they are. A name that finds no file is described as
missing (``sha256: None``): loading the dictionary refuses it anyway, naming it.
"""
from __future__ import annotations

import hashlib
import os
from functools import lru_cache
from pathlib import Path


def file_ref(name: str) -> dict:
    """{"file": name as written, "sha256": hex digest of the bytes Mitsuba reads for it, or
    None when no file is found} (module docstring). The name stays as written, so a scene
    tree referenced by relative names keeps its identity wherever it lies."""
    path = _found(name)
    if path is None:
        return {"file": name, "sha256": None}
    return {"file": name, "sha256": file_sha256(path)}


def file_sha256(path: str | os.PathLike) -> str:
    """Hex sha256 of the file's bytes, read in blocks and remembered by the file's stat (a
    key is made many times a run: every frame of a sequence names the same mesh; an edited
    file is hashed again)."""
    path = Path(path).resolve()
    st = path.stat()
    return _digest(str(path), st.st_mtime_ns, st.st_size, st.st_ino)


def _found(name: str) -> Path | None:
    if not name:
        return None
    candidate = Path(name)
    if not candidate.is_absolute():
        from .mitsuba_env import mitsuba

        candidate = Path(str(mitsuba().file_resolver().resolve(name)))
        if not candidate.is_absolute():  # the resolver gave the name back unchanged
            candidate = Path(os.getcwd()) / candidate
    return candidate.resolve() if candidate.is_file() else None


@lru_cache(maxsize=256)
def _digest(path: str, mtime_ns: int, size: int, inode: int) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


__all__ = ["file_ref", "file_sha256"]
