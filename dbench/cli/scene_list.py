"""The scenes of a comma list: ``sweep --scenes`` (repeatable) and ``render --scene``.

A scene is a catalogue (or plugin) name, a scene file or a folder of renders, and a path may
hold a comma (``/data/my,scene.xml``). The pieces of the list between commas that together
name an existing file or folder are therefore one scene: ``--scenes cornell,/data/my,scene.xml``
is two scenes, not three unknown names (README.md, "Usage"). When the text reads as scenes two
ways, every item of each reading naming a scene (``a.xml,b.xml`` where ``a.xml``, ``b.xml`` and
``a.xml,b.xml`` all exist), it is refused in one line naming both readings, never guessed.
"""
from __future__ import annotations

from contextlib import contextmanager
from pathlib import Path
from typing import Iterator, Sequence

from ..errors import DbenchInputError
from .args import list_items


def _names_a_scene(item: str, known: set[str]) -> bool:
    """Whether ``item`` names a scene as given: a catalogue or plugin scene, an existing file or
    folder, or DIR/VIEW of a folder of renders (dbench.datasets.folders.load)."""
    from ..datasets.folders.load import is_folder_scene

    if not item:  # Path("") is the working directory
        return False
    try:
        return item in known or Path(item).exists() or is_folder_scene(item)
    except (OSError, ValueError):  # a name too long for the system, a NUL byte
        return False


def readings(text: str, known: set[str], most: int = 2) -> list[list[str]]:
    """The ways (up to ``most``) to cut ``text`` at commas so that every item names a scene
    (:func:`_names_a_scene`); items are stripped of the spaces around them, a path's own
    spaces kept."""
    pieces = text.split(",")
    n = len(pieces)
    # ways[i]: readings of pieces[i:], found from the end (each item one piece or more)
    ways: list[list[list[str]]] = [[] for _ in range(n)] + [[[]]]
    for i in range(n - 1, -1, -1):
        for j in range(i + 1, n + 1):
            item = ",".join(pieces[i:j]).strip()
            if ways[j] and _names_a_scene(item, known):
                ways[i] += [[item] + rest for rest in ways[j]][:most - len(ways[i])]
            if len(ways[i]) >= most:
                break
    return ways[0]


def _items(text: str, option: str, known: set[str]) -> list[str]:
    """One text's scenes (module docstring). Where no reading names only scenes, each piece is
    an item except runs of pieces that name an existing file or folder (the longest first), so
    that the name refused later is the unknown one."""
    found = readings(text, known)
    if len(found) > 1:
        shown = [" + ".join(repr(item) for item in r) for r in found]
        raise DbenchInputError(f"{option}: {text!r} reads as scenes two ways, {shown[0]} or "
                               f"{shown[1]}; rename the file or folder whose name holds the "
                               f"comma")
    if found:
        return found[0]
    pieces, items, i = text.split(","), [], 0
    while i < len(pieces):
        j = next((j for j in range(len(pieces), i + 1, -1)
                  if _names_a_scene(",".join(pieces[i:j]).strip(), set())), i + 1)
        items.append(",".join(pieces[i:j]).strip())
        i = j
    if not all(items):
        raise DbenchInputError(f"{option}: an empty item in {text!r}; give a comma list "
                               f"without empty items")
    return items


def scene_names(texts: str | Sequence[str], option: str) -> list[str] | None:
    """The scenes of ``option`` given as ``texts`` (one text per time the option is given):
    None for ``all`` (every scene), else every text's items in order (module docstring),
    each scene once; the rule of every list option (:func:`dbench.cli.args.list_items`)."""
    from ..datasets.scenes import catalogue

    known = set(catalogue.available())
    return list_items(texts, option, lambda text: _items(text, option, known))


@contextmanager
def refusals_naming(option: str) -> Iterator[None]:
    """Refusals of a scene raised inside the block name ``option``, the option the user gave
    (``sweep --scenes``): a scene file's or folder's refusal begins ``--scene PATH:``
    (dbench.datasets.scene_files, dbench.datasets.folders), the option of ``run`` and
    ``render``, which a sweep does not have (README.md, "Usage")."""
    try:
        yield
    except DbenchInputError as exc:
        said = exc.args[0] if len(exc.args) == 1 else None
        if isinstance(said, str) and said.startswith("--scene ") and option != "--scene":
            exc.args = (option + said[len("--scene"):],)
        raise


__all__ = ["readings", "refusals_naming", "scene_names"]
