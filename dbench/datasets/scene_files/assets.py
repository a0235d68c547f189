"""Every file a Mitsuba XML scene reads, found the way Mitsuba 3 finds it, and its bytes' hash.

The cache key of a scene file covers the file and every file it references, so editing the
scene or a texture re-renders exactly its entries (README.md, "Your scene, your renders, any
size"). That promise holds only if dbench hashes the files Mitsuba actually loads, so this
module follows Mitsuba 3's parser (``mi.load_file``, checked against Mitsuba 3.9.1 by
experiment, tests/datasets/test_scene_assets.py) and uses Mitsuba's own ``FileResolver`` for
each look-up:

- every XML file (the scene and each included fragment) is read with a copy of the resolver
  of the file that includes it (for the scene: ``mi.file_resolver()``, which holds the working
  directory Mitsuba started in), with the file's own folder put first;
- ``<path value="DIR"/>`` (a child of a file's root) puts DIR first in that file's resolver; a
  relative DIR is itself looked up with that resolver (so it is relative to the file's folder
  first);
- ``<include filename="F"/>`` and ``<spectrum filename="F"/>`` are looked up when the parser
  reaches them, with the resolver of the file they are in, as it is at that point (a ``<path>``
  further down does not apply to them; a nested include finds files next to its fragment);
- ``<string name="filename" value="F"/>`` (textures, meshes, environment maps, volumes,
  measured BSDFs), in the scene file or in any fragment, is looked up when the objects are
  built, after the whole file is read: with the **scene file's** resolver, holding every
  ``<path>`` of the scene file (wherever it stands in the file) but none of the fragments'
  own ``<path>``s or folders. A fragment in another folder therefore names its textures and
  meshes relative to the scene's folder (or a ``<path>``), not to its own;
- the resolver returns the first folder (most recently put first) in which the name exists,
  else the name unchanged, which is then opened relative to the process's working directory;
  absolute names are used as they are;
- ``$name`` in attributes is replaced as Mitsuba does it (``--scene-param`` values, then
  ``<default>``s in the order the parser meets them, included files sharing them; longer names
  first; ``\\$`` is a literal dollar sign).

A reference that cannot be found (or finds a folder) raises :class:`DbenchInputError` naming
it, the file that refers to it and the folders searched, before anything renders.
"""
from __future__ import annotations

import os
import re
import xml.etree.ElementTree as ET
from pathlib import Path

from ...errors import DbenchInputError
from ..file_refs import file_sha256
from . import markup

#: Mitsuba's limit on nested includes (ParserConfig.max_include_depth), which also stops cycles.
MAX_INCLUDE_DEPTH = 15


def asset_hashes(path: str | Path, params: dict[str, str] | None = None) -> dict[str, str]:
    """{file: sha256 of its bytes} of the scene file at ``path`` (under :data:`SCENE_KEY`) and
    of every file it references (module docstring), each named relative to the scene's folder
    (with ``..`` outside it, so the names do not depend on where the tree is), sorted. DbenchInputError,
    naming the reference and the folders searched, when one cannot be found."""
    return scene_walk(path, params)[0]


def scene_walk(path: str | Path, params: dict[str, str] | None = None
               ) -> tuple[dict[str, str], dict[str, str]]:
    """(:func:`asset_hashes`, {name: value} of the ``<default>``s the files declare, the first
    of each name as the parser meets it, ``$`` parameters in it substituted)."""
    from ..mitsuba_env import mitsuba

    mi = mitsuba()
    scene = Path(path).resolve()
    walk = _Walk(mi, scene, params or {})
    top = walk.read(scene, mi.FileResolver(mi.file_resolver()), depth=0)
    for ref, where in walk.deferred:  # filename strings: built after the whole parse
        walk.found(top, ref, where, "<string name=\"filename\">")
    hashes = dict(sorted((SCENE_KEY if f == scene else _relative(f, scene.parent), file_sha256(f))
                         for f in walk.files))
    return hashes, walk.defaults


class _Walk:
    """One pass over the scene file and its includes in the parser's order."""

    def __init__(self, mi, scene: Path, params: dict[str, str]):
        self.mi = mi
        self.scene = scene
        self.params = {str(k): str(v) for k, v in params.items()}
        self.files: list[Path] = []
        self.defaults: dict[str, str] = {}
        self.deferred: list[tuple[str, Path]] = []

    def read(self, file: Path, parent_resolver, depth: int):
        """Record ``file``, follow its ``<path>``, ``<include>`` and ``<spectrum filename>``
        elements in order, defer its filename strings; return its resolver."""
        if depth >= MAX_INCLUDE_DEPTH:
            raise DbenchInputError(f"--scene {self.scene}: more than {MAX_INCLUDE_DEPTH} nested "
                                   f"<include>s (at {file}); is an include circular?")
        self._add(file)
        try:
            # read as Mitsuba's parser reads it (a Latin-1 comment, a bare "&": markup.py)
            root = markup.root(file.read_bytes())
        except ET.ParseError as exc:
            raise DbenchInputError(f"--scene {self.scene}: {file} is not well-formed XML "
                                   f"({exc})") from None
        resolver = self.mi.FileResolver(parent_resolver)
        resolver.prepend(str(file.parent))
        self._element(root, None, file, resolver, depth)
        return resolver

    def _element(self, el, parent, file: Path, resolver, depth: int) -> None:
        tag = el.tag if isinstance(el.tag, str) else ""
        attr = {k: self._substitute(v, file) for k, v in el.attrib.items()}
        if tag == "default":
            self.defaults.setdefault(attr.get("name", ""), attr.get("value", ""))
            self.params.setdefault(attr.get("name", ""), attr.get("value", ""))
        elif tag == "path" and parent is not None and parent.get("is_root"):
            folder = self.found(resolver, attr.get("value", ""), file, "<path>", folder=True)
            resolver.prepend(str(folder))
        elif tag == "include" and attr.get("filename"):
            inc = self.found(resolver, attr["filename"], file, "<include>")
            self.read(inc, resolver, depth + 1)
        elif tag == "spectrum" and attr.get("filename") and "type" not in attr:
            self.found(resolver, attr["filename"], file, "<spectrum filename>")
        elif tag == "string" and attr.get("name") == "filename":
            self.deferred.append((attr.get("value", ""), file))
        if tag == "transform":
            return  # its children are transform operations, never files
        here = {"is_root": parent is None}
        for child in el:
            self._element(child, here, file, resolver, depth)

    def found(self, resolver, ref: str, where: Path, what: str, folder: bool = False) -> Path:
        """The file (or, for ``<path>``, folder) Mitsuba opens for ``ref``."""
        hit = Path(str(resolver.resolve(ref))) if ref else None
        if hit is not None and not hit.is_absolute():
            hit = Path(os.getcwd()) / hit  # the resolver gave the name back unchanged
        if hit is None or not hit.exists() or (not folder and not hit.is_file()):
            kind = "folder" if folder else "file"
            if hit is not None and hit.is_dir() and not folder:
                why = f"is a folder ({hit})"
            elif Path(ref).is_absolute():
                why = "not found"
            else:
                # each folder once, in the resolver's order (a scene's own folder is in it
                # twice when the loader and the file itself both prepend it)
                searched = list(dict.fromkeys(str(p) for p in resolver))
                searched.append(f"{os.getcwd()} (working directory)")
                why = f"not found in the folders Mitsuba searches: {'; '.join(searched)}"
            raise DbenchInputError(f"--scene {self.scene}: {kind} {ref!r} ({what} in {where}) "
                                   f"{why}")
        if not folder:
            self._add(hit)
        return hit.resolve()

    def _add(self, f: Path) -> None:
        f = f.resolve()
        if f not in self.files:
            self.files.append(f)

    def _substitute(self, value: str, file: Path) -> str:
        """``$name`` replaced as Mitsuba's parser does it (longer names first)."""
        if "$" not in value:
            return value
        for key in sorted(self.params, key=len, reverse=True):
            value = re.sub(r"(?<!\\)\$" + re.escape(key), lambda m: self.params[key], value)
        left = re.search(r"(?<!\\)\$([A-Za-z0-9_]*)", value)
        if left:
            name = left.group(1)
            # --scene-param takes names only (scene_files/load.parse_scene_params): "$1" or a
            # lone "$" is no parameter it could give
            # (a sweep's other scenes may have no such parameter: the scoped form names this one)
            fix = (f"give it with --scene-param {name}=VALUE (SCENE:{name}=VALUE for this "
                   f"scene alone, SCENE as the command names it) or a <default>"
                   if re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", name)
                   else "a parameter's name starts with a letter or _; write \\$ for a $ itself")
            raise DbenchInputError(f"--scene {self.scene}: undefined parameter ${name} in "
                                   f"{file}; {fix}")
        return value.replace("\\$", "$")


#: The scene file's own entry in :func:`asset_hashes`: by its bytes, not its name, so a renamed
#: copy is the same scene (its identity in caches and sweeps is its content: README.md).
SCENE_KEY = "(the scene file)"


def _relative(f: Path, folder: Path) -> str:
    # relative even outside the folder ("../fragments/room.xml"): a scene tree moved or copied
    # elsewhere keeps its identity, where an absolute name would make it another scene
    return Path(os.path.relpath(f.resolve(), folder.resolve())).as_posix()


__all__ = ["asset_hashes", "scene_walk", "MAX_INCLUDE_DEPTH", "SCENE_KEY"]
