"""A sweep's scenes: the labels their cells are filed and tabled under, and the checks every
scene passes before the sweep touches its folder (:func:`check_scenes`).

A sweep writes one cell file per (scene, spp, method label) (dbench/run/sweep.py; README.md,
the ``dbench sweep`` paragraph). A scene's identity in a cell is its fingerprint
(:func:`dbench.datasets.scene_fingerprint`), never its name; the label only has to keep two
scenes' cells apart when their names are the same, as two scene files ``a/cbox.xml`` and
``b/cbox.xml`` or two folders holding views of one name are.
"""
from __future__ import annotations

from pathlib import Path

from .. import io


def scene_labels(config, out: str | Path | None = None) -> dict[str, str]:
    """{scene as given: label}, the name a scene's cells are filed and tabled under.

    A scene keeps its name (so catalogue scenes and every scene file, folder or plugin scene
    whose name no other scene of the sweep has keep the cells and identities they always had).
    Scenes of one name from different places (``a/cbox.xml``, ``b/cbox.xml``; folders holding
    views of one name) share it out: a catalogue scene keeps the name, else the first of them in
    the sweep's order (``sweep.json``'s scenes, then this run's new ones; an extended sweep never
    renames a label); each other one is labelled with the shortest end of its path that no
    other of them shares (``b/cbox.xml``). The same place given twice is one scene, one label.
    """
    before: list = []
    if out is not None:
        try:
            stored = io.read_json(Path(out) / "sweep.json")
        except (OSError, ValueError):
            stored = {}
        stored = stored if isinstance(stored, dict) else {}
        before = [s for s in ((stored.get("config") or {}).get("scenes") or [])
                  if isinstance(s, str)]
    specs = before + [s for s in dict.fromkeys(config.scenes) if s not in before]
    groups: dict[str, list[tuple[str, Path | None]]] = {}
    for spec in specs:
        place = scene_place(config, spec)
        if place is not None:
            groups.setdefault(place[0], []).append((spec, place[1]))
    labels = {spec: spec for spec in config.scenes}  # unresolvable: refused by config.scene
    for name, members in groups.items():
        places = list(dict.fromkeys(p for _, p in members))
        owner = None if None in places else places[0]
        for spec, place in members:
            labels[spec] = name if place == owner else _distinct_end(place, places)
    return {spec: labels[spec] for spec in config.scenes}


def scene_place(config, spec: str) -> tuple[str, Path | None] | None:
    """(name, where it lives) of a scene as given: (name, None) for a catalogue scene, the
    resolved path of a scene file, folder/view of a folder of renders; None when it does not
    resolve (a scene of an earlier run that is gone)."""
    from ..datasets.scene_files import load as scene_files
    from ..datasets.scenes import catalogue

    if spec in catalogue.available():
        return spec, None
    try:
        if scene_files.is_scene_file(spec):
            p = Path(spec).expanduser().resolve()
            return p.name, p
        sc = config.scene(spec)
    except Exception:  # noqa: BLE001 - a stored scene that no longer loads names nothing
        return None
    info = getattr(sc, "info", None)
    return (sc.name, Path(info.path).resolve() / sc.name) if info is not None else (sc.name, None)


def _distinct_end(place: Path | None, places: list) -> str:
    """The shortest end of ``place`` (2 parts or more) that no other place ends in."""
    if place is None:
        return "?"
    parts = place.parts
    for k in range(2, len(parts) + 1):
        end = parts[-k:]
        if all(other is None or other == place or other.parts[-k:] != end for other in places):
            return Path(*end).as_posix()
    return place.as_posix()


def check_scenes(config) -> None:
    """Refuse, before anything is written or rendered, a scene of the sweep that its turn would
    refuse (README.md, "Usage"; the ``dbench sweep`` paragraph):
    a plugin's steady scene whose dictionary Mitsuba cannot load or whose film filter is not a
    box (:func:`dbench.datasets.scenes.build.check_plugin_scene`), a sequence shorter than
    ``--frames``, a transient film too large at the sweep's size and bins
    (:func:`dbench.datasets.transient.scene.check_bins`), a folder of renders that
    does not hold the sweep's size, seeds, reference spp (:func:`folder_ref_spp`) or every
    spp, or whose statistics were gathered with another transform than a ``--transform``
    given, or whose reference is black, and ``--normal-encoding`` where no scene is a folder of
    renders. A folder is checked by the very loads its groups make
    (:func:`dbench.run.inputs.load_seeds`, which refuse such settings as ``dbench run`` does),
    reading only the colour of its first frame per spp and its reference once, and its
    statistics' transform by :func:`dbench.datasets.check_folder_transform`. The references
    of the scenes dbench renders are checked by :func:`render_references`. A
    film of another size than the sweep's is refused by :func:`dbench.run.sweep.plan`, whose
    fingerprints build every scene's dictionary before the run is recorded."""
    from .. import datasets
    from ..datasets.scenes.build import check_plugin_scene
    from ..datasets.transient.scene import check_bins
    from ..errors import DbenchInputError
    from .inputs import load_seeds

    folders = 0
    for name in dict.fromkeys(config.scenes):
        scene = config.scene(name)
        folders += not scene.renders
        if scene.renders:
            if scene.kind == "steady":  # the kind datasets.load probes, before rendering
                check_plugin_scene(scene)
            elif scene.kind == "sequence" and config.frames is not None \
                    and not 1 <= config.frames <= scene.n_frames:
                raise DbenchInputError(f"--frames: expected an integer in [1, "
                                       f"{scene.n_frames}] for {name}, got {config.frames}")
            elif scene.kind == "transient":  # the film's memory, at its default bins too
                check_bins(scene.window(config.bins).bins, config.res_for(scene),
                           "--bins" if config.bins is not None else f"{name}'s bins")
            continue
        frames = kind_options(config, scene)["frames"]
        datasets.check_folder_frames(scene, frames)
        for i, spp in enumerate(config.spp):
            # the first load reads the reference too, over every frame the sweep takes:
            # load_seeds refuses a black one (dbench.run.inputs.check_reference_lit)
            ref = i == 0 and "reference" in scene.provides
            load_seeds(scene, config.seed, config.seeds, spp=spp, res=config.res_for(scene),
                       needs=("reference",) if ref else (), frames=frames if ref else 1,
                       ref_spp=folder_ref_spp(config, scene), progress=False)
            # its statistics' transform, as the folder's scan read it
            datasets.check_folder_transform(scene, spp, config.transform, config.lam)
    if config.normal_encoding is not None and not folders:
        raise DbenchInputError(f"--normal-encoding: none of the sweep's scenes "
                               f"({', '.join(config.scenes)}) is a folder of renders; dbench "
                               f"renders the others, with signed normals")




def render_references(config, names, progress: bool = True) -> float:
    """Render the reference of each scene of ``names`` (scenes dbench renders; a folder's is
    checked by :func:`check_scenes`) once, into the cache the groups read it from, and refuse a
    reference that is 0 in every pixel (:func:`dbench.run.inputs.check_reference_lit`, as
    ``dbench run`` refuses it) before the sweep writes anything to its folder (README.md, the
    ``dbench sweep`` paragraph). Under ``--no-cache`` nothing keeps the reference for the
    groups, so each is rendered once more by its first group. Returns the seconds taken."""
    import time

    from .. import datasets
    from .inputs import check_reference_lit

    t0 = time.perf_counter()
    cache = datasets.Cache(config.cache, enabled=not config.no_cache)
    for name in names:
        scene = config.scene(name)
        if not scene.renders:
            continue
        # the albedo warms the groups' feature render; under --no-cache it would be wasted
        needs = {"reference"} | (set() if config.no_cache else {"albedo"})
        frame = datasets.load(scene, spp=1, res=config.res_for(scene), needs=needs,
                              seed=config.seed, ref_seed=config.seed, ref_spp=config.ref_spp,
                              cache=cache, **kind_options(config, scene), progress=progress)
        check_reference_lit(frame, scene.name)
    return time.perf_counter() - t0


def folder_ref_spp(config, scene) -> int | None:
    """The ``--ref-spp`` the sweep ``config`` loads ``scene`` with: the option itself for a
    scene the sweep renders; for a folder of renders, the value its loads check against
    (:func:`dbench.run.inputs.load_seeds` refuses a mismatch): the option where the folder
    states its reference's spp (they must agree) or where every scene is a folder (as in
    ``dbench run``, an option that would apply to nothing is refused); None where the folder
    states none and the sweep renders other scenes, for which ``--ref-spp`` is given: the
    folder's cells then record its reference spp as unknown (docs/formats.md)."""
    if scene.renders or config.ref_spp is None or scene.info.ref_spp is not None:
        return config.ref_spp
    return None if any(config.scene(n).renders for n in config.scenes) else config.ref_spp


def kind_options(config, scene) -> dict:
    """``frames`` and ``bins`` as ``scene`` takes them: each is read by one kind of scene alone
    (README.md, "Usage": refused only where none of a sweep's scenes reads it), so in a sweep
    mixing kinds the others get None, load and cell identity alike."""
    return {"frames": config.frames if scene.kind == "sequence" else None,
            "bins": config.bins if scene.kind == "transient" else None}


__all__ = ["check_scenes", "folder_ref_spp", "kind_options", "render_references",
           "scene_labels", "scene_place"]
