"""Renders from a folder of EXR files: the OIDN training-set layout and multi-layer EXR files.

A folder holds one or more *views*; every file name starts with the view name (docs/formats.md
§1-2):

``<view>_<spp>.<tag>.exr``
    One buffer per file (OIDN layout). ``<spp>`` is digits (a count in [1, 2³¹ − 1]), zero
    padding allowed, optionally followed by ``spp``; ``ref``, ``reference``, ``gt`` or
    ``target`` instead names the reference. Tags: ``hdr`` colour, ``alb`` albedo, ``nrm`` normal (OIDN's), and dbench's
    ``depth`` (1 channel), ``pos`` position, ``emitter`` (1 channel, in [0, 1]), ``var`` the
    variance σ² of ONE sample of the colour (pbrt-v4's ``Variance`` convention; the variance
    of the mean is σ²/spp), ``mv`` motion (2 channels). ``ldr`` and ``sh1x/y/z`` files are
    recognised and ignored (listed in :attr:`FolderInfo.ignored`).
``<view>_<spp>.exr``, ``<view>_ref.exr``
    Several buffers as named channels (Mitsuba's ``aov`` integrator, pbrt-v4's gbuffer film,
    dbench's :func:`dbench.io.write_exr`), resolved by the alias table of
    :mod:`dbench.datasets.folders.exr_layers`. One-buffer and multi-layer files may be mixed; one
    buffer of one spp found in two files is an error naming both.
``<view>_<spp>.stats.npz``, ``<view>_ref.stats.npz``
    dbench's exact float64 statistics (``n``, ``mean``, ``var_mean``, ``m3``, ``transform``,
    ``lam``: the fields of :class:`~dbench.data.SampleStats`), preferred over a variance image;
    the reference's gives its variance where its transform is the identity.
``<view>_f<frame>_<spp>.<tag>.exr``
    Numbered frames of a sequence (``walk_f0003_0004.hdr.exr``, motion in ``.mv.exr``); every
    frame must have the files the others have, and the numbers must be consecutive (motion
    points to the frame before).
``dataset.json`` (optional)
    ``{"ref_spp": int, "ev": float, "normal_encoding": "signed"|"unsigned", "description":
    str, "scene": str}`` (``"normals"``, as :mod:`dbench.datasets.folders.export` writes it, is read
    as ``"normal_encoding"``).

Reference: the named one; without one the highest spp serves and is not offered as a noisy spp
(``reference_from == "highest-spp"``); a single spp and no reference is an error. Colour, noisy
or reference, must be finite (:func:`~dbench.datasets.folders.exr_layers.refuse_non_finite`).
The reference is judged, not trusted (:mod:`dbench.datasets.folders.reference`): its variance of the mean comes from its
``var`` image / ``Variance`` divided by ``ref_spp`` (or an identity-transform ``.stats.npz``'s
``var_mean``), else is estimated from its spp and the noisy series, or from the series'
convergence; when nothing gives it the frame has no ``reference_var``, ``meta["ref_rmse"]`` is
NaN (reports say "unknown", never 0; so are ``rmse_unbiased`` and ``relmse_unbiased``,
:mod:`dbench.metrics.judge`) and ``meta["ref_var_known"]`` is False. A reference no better than
the noisy input gets ``meta["reference_warning"]``. Features missing for an spp are taken from
the reference's files (OIDN training sets may store clean features once); a feature that only
some spp have and the reference lacks is left out at every spp, and ``meta["feature_warning"]``
says which spp lack which buffer (:mod:`dbench.datasets.folders.features`). Normals stored as
n·0.5 + 0.5 are detected at scan time on the first normal image
(:mod:`dbench.datasets.folders.normals`) and decoded to [-1, 1] for the whole view;
``dataset.json`` "normal_encoding" overrides the detection, and ``dbench run
--normal-encoding`` (:func:`with_normal_encoding`) overrides both. ``meta["layers_read"]``
and ``meta["layers_ignored"]`` list the files and channels read and left.

A folder with several views is selected by ``DIR/NAME`` (a path whose parent is the folder and
whose last part is the view name).

Example:
    >>> info = scan_folder("renders/kitchen")                      # doctest: +SKIP
    >>> info.spps, info.reference_from, sorted(info.buffers)       # doctest: +SKIP
    ((4, 16), 'file', ['albedo', 'color', 'normal', 'reference'])
    >>> frame = load_folder(info, 4, needs={"albedo"})             # doctest: +SKIP
"""
from __future__ import annotations

import hashlib
import json
import os
import re
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Iterable

import numpy as np

from ...data import MAX_COUNT, Frame, SampleStats
from ...errors import DbenchInputError
from ...resolution import Res
from . import exr_layers as xl
from . import features as feat
from .export import check_variance, read_dataset_json, read_stats_npz
from .features import FEATURES
from .reference import folder_reference
from .normals import BY_OPTION, ENCODINGS, resolve as resolve_normals

TAGS = {"hdr": "color", "alb": "albedo", "nrm": "normal", "depth": "depth", "pos": "position",
        "emitter": "emitter", "var": "variance", "mv": "motion"}
IGNORED_TAGS = ("ldr", "sh1x", "sh1y", "sh1z")
REF_KEYS = ("ref", "reference", "gt", "target")
STATS_FROM_VARIANCE = "variance image (identity transform, no third moment)"
PATTERNS = ("<name>_<spp>.<tag>.exr (tag: hdr, alb, nrm, depth, pos, emitter, var, mv, ldr, "
            "sh1x/y/z)", "<name>_ref.<tag>.exr", "<name>_<spp>.exr (multi-layer)",
            "<name>_<spp>.stats.npz", "<name>_ref.stats.npz",
            "<name>_f<frame>_<spp>.<tag>.exr")
_NAME = re.compile(
    r"(?P<view>.+?)(?:_f(?P<frame>\d+))?_(?P<key>\d+(?:spp)?|ref|reference|gt|target)"
    r"(?:\.(?P<tag>hdr|ldr|sh1[xyz]|alb|nrm|depth|pos|emitter|var|mv|stats))?\.(?P<ext>exr|npz)",
    re.I)


@dataclass(frozen=True, eq=False)
class FolderInfo:
    """What :func:`scan_folder` found for one view (see the module docstring).

    ``normals`` is resolved at scan time (declared in ``dataset.json`` or detected on the
    first normal image; :func:`with_normal_encoding` gives the command line's).
    ``fingerprint``: 16 hex chars of sha256 over (file name, bytes) of every file the view
    uses, plus ``dataset.json`` and a ``--normal-encoding`` given. ``ignored``: files
    recognised but unused.
    ``reference_from`` is never None from :func:`scan_folder` (a view without any reference is
    an error there); ``ref_spp`` is None for a named reference unless ``dataset.json`` gives it.
    """

    path: Path
    name: str
    width: int
    height: int
    spps: tuple[int, ...]
    ref_spp: int | None
    reference_from: str | None
    buffers: frozenset[str]
    stats_source: str | None
    frames: tuple[int, ...] | None
    ev: float
    normals: str
    fingerprint: str
    ignored: tuple[str, ...]
    #: {(frame or None, spp or "ref"): {buffer: exr_layers.Layer, or Path for "stats"}}
    _plan: dict = field(default_factory=dict, repr=False)
    _meta: dict = field(default_factory=dict, repr=False)
    #: the encoding ``dataset.json`` declares, or None
    _declared_normals: str | None = field(default=None, repr=False)
    #: {spp: (transform, λ)} its statistics were gathered with (a variance image: identity)
    stats_settings: dict = field(default_factory=dict)


def _parse(name: str) -> re.Match | None:
    # a reference's .stats.npz is parsed too: its identity statistics give the reference's
    # variance (reference.known_variance)
    m = _NAME.fullmatch(name)
    if m is None or (m["ext"].lower() == "npz") != ((m["tag"] or "").lower() == "stats"):
        return None
    return m


def _listing(folder: Path) -> list[str]:
    # Hidden names are skipped: atomic writes leave ".<name>.*.tmp.exr" while in flight.
    return sorted(p.name for p in folder.iterdir() if p.is_file() and not p.name.startswith("."))


def _select(path: Path) -> tuple[Path, str, list[str], list[str]]:
    """(folder, view, the view's files, unrecognised EXR files)."""
    if path.is_dir():
        folder, want = path, None
    elif path.parent.is_dir() and path.name:
        folder, want = path.parent, path.name
    else:
        raise DbenchInputError(f"{path}: no such folder (expected a folder of EXR files or "
                               "DIR/NAME selecting one view)")
    names = _listing(folder)
    parsed = {n: m for n in names if (m := _parse(n)) is not None}
    views = sorted({m["view"] for m in parsed.values()})
    unknown = [n for n in names if n not in parsed and n.lower().endswith(".exr")]
    if not views:
        found = ", ".join(names[:12]) + (" …" if len(names) > 12 else "") if names else "nothing"
        raise DbenchInputError(f"{path}: no renders in a known layout (found {found}); "
                               f"expected {'; '.join(PATTERNS)}")
    if want is None and len(views) > 1:
        raise DbenchInputError(f"{folder}: holds several views ({', '.join(views)}); pass "
                               f"{folder}/NAME to choose one, e.g. {folder / views[0]}")
    view = want or views[0]
    if view not in views:
        raise DbenchInputError(f"{path}: no files of view {view!r} in {folder} (views: "
                               f"{', '.join(views)})")
    return folder, view, [n for n, m in parsed.items() if m["view"] == view], unknown


def _check_frames(folder: Path, files: list[str]) -> tuple[int, ...] | None:
    """Sorted frame numbers, or None; a frame lacking a file the others have is an error."""
    matches = {n: _parse(n) for n in files}
    numbered = [n for n, m in matches.items() if m["frame"] is not None]
    if not numbered:
        return None
    if len(numbered) != len(files):
        plain = sorted(set(files) - set(numbered))[0]
        raise DbenchInputError(f"{folder / plain}: no frame number, while other files of this "
                               "view have one (_f<frame>); expected all or none")
    pattern = {}
    for n in numbered:
        m = matches[n]
        pattern.setdefault(int(m["frame"]), {})[
            n[:m.start("frame")] + "#" + n[m.end("frame"):]] = m["frame"]
    every = set().union(*pattern.values())
    for k in sorted(pattern):
        for missing in sorted(every - set(pattern[k])):
            width = len(next(iter(pattern[k].values())))
            raise DbenchInputError(f"{folder / missing.replace('#', f'{k:0{width}d}')}: missing; "
                                   f"frame {k} lacks a file the other frames have")
    numbers = sorted(pattern)
    # motion vectors point to the previous frame and the temporal figures difference neighbours:
    # a gap would pair frames that do not follow each other, silently
    absent = sorted(set(range(numbers[0], numbers[-1] + 1)) - set(numbers))
    if absent:
        view = matches[numbered[0]]["view"]
        raise DbenchInputError(f"{folder / view}: frames {numbers[0]}-{numbers[-1]} lack "
                               f"frame{'s' if len(absent) > 1 else ''} "
                               f"{', '.join(map(str, absent[:5]))}{' …' if len(absent) > 5 else ''}"
                               "; expected consecutive frame numbers (a sequence's motion "
                               "vectors point to the frame before)")
    return tuple(numbers)


def _add(slot: dict, buffer: str, source, folder: Path) -> None:
    old = slot.get(buffer)
    if old is not None:
        old_file = old if isinstance(old, Path) else old.file
        new_file = source if isinstance(source, Path) else source.file
        raise DbenchInputError(f"{new_file}: {buffer} is also in {old_file.name}; expected "
                               f"one file per buffer in {folder}")
    slot[buffer] = source


def _window(window: xl.Window) -> str:
    (x0, y0), (x1, y1) = window
    return f"({x0}, {y0})-({x1}, {y1})"


def _build_plan(folder: Path, files: list[str]):
    """{(frame, key): {buffer: Layer | Path}}, the (H, W) of every EXR, unused channels."""
    plan: dict = {}
    size: tuple[tuple[int, int], str, xl.Window] | None = None
    unused: dict[str, list[str]] = {}
    ignored = []
    for name in files:
        m = _parse(name)
        tag = (m["tag"] or "").lower()
        if tag in IGNORED_TAGS:
            ignored.append(name)
            continue
        key = m["key"].lower()
        key = "ref" if key in REF_KEYS else int(key.removesuffix("spp"))
        path = folder / name
        if key != "ref" and not 1 <= key <= MAX_COUNT:  # (a 0-spp file skewed the series)
            raise DbenchInputError(f"{path}: spp {key} in its name; expected a sample count in "
                                   f"[1, {MAX_COUNT}] (<name>_<spp>.<tag>.exr)")
        slot = plan.setdefault((None if m["frame"] is None else int(m["frame"]), key), {})
        if tag == "stats":
            _add(slot, "stats", path, folder)
            continue
        hw, channels, window = xl.exr_header(path)
        if size is None:
            size = (hw, name, window)
        elif hw != size[0]:
            raise DbenchInputError(
                f"{path}: {hw[1]}x{hw[0]} pixels, while {size[1]} has {size[0][1]}x"
                f"{size[0][0]} (width x height); expected one size for the whole view")
        elif window != size[2]:
            # pixels are read from the data window alone: the same size elsewhere in the
            # plane would be compared pixel by pixel, offset
            raise DbenchInputError(
                f"{path}: data window {_window(window)}, while {size[1]} has "
                f"{_window(size[2])} ((x min, y min)-(x max, y max)); expected one data "
                "window for the whole view")
        if tag:
            _add(slot, TAGS[tag], xl.layer_for_tag(path, channels, TAGS[tag]), folder)
        else:
            layers, left = xl.layers_of(path, channels)
            for buffer, layer in layers.items():
                _add(slot, buffer, layer, folder)
            if left:
                unused[name] = left
    if size is None:
        raise DbenchInputError(f"{folder}: no EXR image of this view (found {', '.join(files)})"
                               f"; expected {'; '.join(PATTERNS)}")
    return plan, size[0], unused, ignored


def _fingerprint(folder: Path, names: Iterable[str], info_json: dict) -> str:
    """The folder's identity: the bytes of the renders it uses, and ``dataset.json`` by what it
    says (its keys and values), so re-indenting the file keeps the folder's cells."""
    h = hashlib.sha256()
    for name in sorted(set(names)):
        h.update(name.encode() + b"\0")
        if name == "dataset.json":
            data = json.dumps(info_json, sort_keys=True, separators=(",", ":")).encode()
        else:
            with open(folder / name, "rb") as fh:
                data = fh.read()
        h.update(len(data).to_bytes(8, "little") + data)
    return h.hexdigest()[:16]


def scan_folder(path: str | os.PathLike) -> FolderInfo:
    """Find one view's renders in ``path`` (a folder, or DIR/NAME) and check them.

    Reads EXR headers, the first normal image (encoding detection) and every file's bytes
    (fingerprint); no other pixels. Every inconsistency is a DbenchInputError naming a file.
    """
    folder, view, files, unknown = _select(Path(path))
    info_json = read_dataset_json(folder)
    frames = _check_frames(folder, files)
    plan, (h, w), unused, ignored = _build_plan(folder, files)
    fr = frames[0] if frames else None
    spps = sorted(k for f, k in plan if f == fr and k != "ref")
    if not spps:
        raise DbenchInputError(f"{folder / sorted(files)[0]}: only a reference, no noisy image; "
                               f"expected {view}_<spp>.hdr.exr beside it")
    declared = info_json.get("ref_spp")
    if (fr, "ref") in plan:
        reference_from, ref_spp = "file", declared
    elif len(spps) >= 2:
        reference_from, ref_spp = "highest-spp", spps.pop()
        if declared is not None and declared != ref_spp:
            raise DbenchInputError(f"{folder / 'dataset.json'}: ref_spp {declared}, but no "
                                   f"reference is named and the highest spp is {ref_spp}")
        for f in {f for f, _ in plan}:
            plan[(f, "ref")] = plan.pop((f, ref_spp))
    else:
        one = sorted(files)[0]
        raise DbenchInputError(
            f"{folder / one}: the only spp ({spps[0]}) and no reference; "
            f"expected {view}_ref.hdr.exr (or _reference/_gt/_target) or a second spp")
    for (f, key), slot in plan.items():
        if "color" not in slot:
            some = next(iter(slot.values()))
            some = some if isinstance(some, Path) else some.file
            label = "the reference" if key == "ref" else f"spp {key}"
            raise DbenchInputError(f"{some}: no colour image for {label}; expected "
                                   f"{some.name.split('.')[0]}.hdr.exr or R,G,B channels in "
                                   f"{some.name.split('.')[0]}.exr")
    slots = [plan[(fr, s)] for s in spps]
    ref = plan[(fr, "ref")]
    buffers = {"color", "reference"}
    buffers |= {b for b in FEATURES if all(b in s or b in ref for s in slots)}
    # a feature only some spp have, and the reference not: left out at every spp, and said
    left = feat.left_out(feat.gaps({s: set(slot) for s, slot in zip(spps, slots)}), set(ref),
                         view, {b: t for t, b in TAGS.items()})
    sources = ["stats" if "stats" in s else "variance" if "variance" in s else None
               for s in slots]
    stats_source = None
    stats_settings: dict[int, tuple[str, float]] = {}
    lacking = [spp for spp, src in zip(spps, sources) if src is None]
    if lacking and len(lacking) < len(spps):  # as a feature: left out of the whole series
        left = "; ".join(filter(None, (left, feat.stats_left_out(lacking, view))))
    if None not in sources:
        buffers.add("stats")
        parts: dict[str, list[int]] = {}
        for s, spp, src in zip(slots, spps, sources):
            stats_settings[spp] = (("identity", 0.5) if src == "variance" else
                                   read_stats_npz(s["stats"], settings_only=True))
            desc = STATS_FROM_VARIANCE if src == "variance" else \
                f"dbench statistics ({stats_settings[spp][0]})"
            parts.setdefault(desc, []).append(spp)
        stats_source = (next(iter(parts)) if len(parts) == 1 else
                        "; ".join(f"{d} for spp {', '.join(map(str, v))}"
                                  for d, v in parts.items()))
    declared = info_json.get("normal_encoding") or info_json.get("normals")
    encoding = _normals(slots + [ref], declared)
    used = [n for n in files if n not in ignored]
    if (folder / "dataset.json").exists():
        used.append("dataset.json")
    return FolderInfo(
        path=folder, name=view, width=w, height=h, spps=tuple(spps), ref_spp=ref_spp,
        reference_from=reference_from, buffers=frozenset(buffers), stats_source=stats_source,
        stats_settings=stats_settings,
        frames=frames, ev=float(info_json.get("ev", 0.0) or 0.0),
        normals=encoding.encoding if encoding else "signed",
        fingerprint=_fingerprint(folder, used, info_json), ignored=tuple(sorted(ignored + unknown)),
        _plan=plan, _meta={"unused_channels": unused, "description":
                           info_json.get("description", ""), "declared_scene":
                           info_json.get("scene", ""),
                           "normal_encoding": encoding.text if encoding else "",
                           "normal_warning": encoding.warning if encoding else "",
                           "feature_warning": left},
        _declared_normals=declared)


def _normals(slots: list[dict], declared: str | None, given: str | None = None):
    """:func:`dbench.datasets.folders.normals.resolve` on the first normal image of ``slots``
    (the noisy spp's, then the reference's)."""
    layer = next((s["normal"] for s in slots if "normal" in s), None)
    return resolve_normals(
        declared, None if layer is None else xl.stack(xl.read_channels(layer.file), layer),
        "" if layer is None else f"{layer.file.name} ({', '.join(layer.channels)})", given)


def with_normal_encoding(info: FolderInfo, encoding: str) -> FolderInfo:
    """``info`` with the normals' encoding given by ``dbench run --normal-encoding``: it wins
    over ``dataset.json`` and the detection (:mod:`dbench.datasets.folders.normals`),
    ``meta["normal_encoding"]`` says so, and the fingerprint covers it, so that results under
    another encoding never share an identity (a sweep cell, a cache entry) with these."""
    if encoding not in ENCODINGS:
        raise DbenchInputError(f"{BY_OPTION}: {encoding!r}; valid: {', '.join(ENCODINGS)}")
    fr = info.frames[0] if info.frames else None
    found = _normals([info._plan[(fr, k)] for k in (*info.spps, "ref")],
                     info._declared_normals, encoding)
    key = hashlib.sha256(f"{info.fingerprint}\0{BY_OPTION} {encoding}".encode())
    return replace(info, normals=found.encoding, fingerprint=key.hexdigest()[:16],
                   _meta={**info._meta, "normal_encoding": found.text,
                          "normal_warning": found.warning})


def is_folder_scene(text: str, any_view: bool = False) -> bool:
    """True when ``text`` names an existing folder, or DIR/NAME where DIR holds files of view
    NAME (``any_view``: of any view) in a known layout. Never raises."""
    try:
        p = Path(text)
        if text and p.is_dir():
            return True
        if not p.name or not p.parent.is_dir():
            return False
        return bool(text) and any((m := _parse(n)) is not None and (any_view or m["view"] ==
                                  p.name) for n in _listing(p.parent))
    except (OSError, ValueError):
        return False


def load_folder(info_or_path: FolderInfo | str | os.PathLike, spp: int,
                needs: Iterable[str] | None = None, frame: int | None = None) -> Frame:
    """A :class:`~dbench.data.Frame` of one spp with exactly the buffers in ``needs``.

    Args:
        info_or_path: a :class:`FolderInfo` or a path for :func:`scan_folder`.
        spp: one of ``info.spps``.
        needs: buffer names (``color`` always comes; None: every buffer in ``info.buffers``);
            ``reference`` brings ``reference_var`` and, when the folder has one, ``emitter``.
        frame: the frame number for a sequence folder (one of ``info.frames``), else None.
    Returns:
        Frame with (H, W, C) float32 buffers, ``stats`` as float64 SampleStats (exact from a
        ``.stats.npz``; from a variance image: identity transform, var_mean = σ²/spp, m3 = 0)
        and ``meta`` describing the files (module docstring).
    """
    info = info_or_path if isinstance(info_or_path, FolderInfo) else scan_folder(info_or_path)
    where = f"{info.path}/{info.name}"
    if info.frames is None and frame is not None:
        raise DbenchInputError(f"{where}: frame {frame!r} asked of a view without numbered "
                               "frames; expected frame=None")
    if info.frames is not None and frame not in info.frames:
        raise DbenchInputError(f"{where}: frame {frame!r}; expected one of {list(info.frames)}")
    if isinstance(spp, bool) or spp not in info.spps:
        raise DbenchInputError(f"{where}: spp {spp!r} is not offered; expected one of "
                               f"{list(info.spps)}")
    wanted = set(info.buffers if needs is None else needs) | {"color"}
    missing = wanted - info.buffers
    if missing:
        raise DbenchInputError(f"{where}: no {', '.join(sorted(missing))} buffer; available: "
                               f"{', '.join(sorted(info.buffers))}")
    if "reference" in wanted and "emitter" in info.buffers:
        wanted.add("emitter")
    slot, ref = info._plan[(frame, spp)], info._plan[(frame, "ref")]
    read = xl.Reader()
    files: dict[str, str] = {"color": slot["color"].file.name}
    color = xl.refuse_non_finite(read(slot["color"]), slot["color"].file, "colour")
    buffers: dict[str, np.ndarray] = {}
    for b in sorted(wanted & set(FEATURES)):
        layer = slot.get(b) or ref[b]
        buffers[b] = read(layer)
        files[b] = layer.file.name
    if "normal" in buffers:
        buffers["normal"] = xl.decode_normals(buffers["normal"], info.normals)
    gaps = feat.gaps({s: set(info._plan[(frame, s)]) for s in info.spps})
    stats = None
    if "stats" in wanted:
        if "stats" in slot:
            stats = read_stats_npz(slot["stats"], color.shape, spp=int(spp))
            files["stats"] = slot["stats"].name
        else:
            sigma2 = check_variance(read(slot["variance"]).astype(np.float64),
                                    str(slot["variance"].file), color)
            stats = SampleStats(n=float(spp), mean=color.astype(np.float64),
                                var_mean=sigma2 / spp, m3=np.zeros(color.shape),
                                transform="identity", lam=0.5)
            files["stats"] = slot["variance"].file.name
    meta = {"scene": f"{info.path.name}/{info.name}", "kind": "steady", "spp": int(spp),
            "res": Res(info.width, info.height).key, "source": "folder", "path": str(info.path),
            "files": files, "normals": info.normals, "stats_source": info.stats_source,
            "ref_spp": info.ref_spp, "reference_from": info.reference_from, "ev": info.ev,
            "render_s": None, "cache_hits": [], "rendered": [],
            "versions": {"variant": "files"}}
    if frame is not None:
        meta["frame"] = int(frame)
    meta.update({k: v for k, v in info._meta.items() if v})
    if "reference" in wanted:
        buffers["reference"] = xl.refuse_non_finite(read(ref["color"]), ref["color"].file,
                                                     "reference")
        files["reference"] = ref["color"].file.name
        # judged, not trusted: its noise estimated from what the folder holds ("unknown",
        # never 0, when nothing does) and a warning when it is no better than the input
        buffers["reference_var"], ref_meta, lights = folder_reference(
            info, frame, spp, read, files, buffers["reference"], buffers)
        if lights is not None:  # no emitter buffer: the judge's surface is the check's
            buffers["judged_lights"] = lights
        meta.update(ref_seed=None, **ref_meta)
    if "normal" not in buffers:
        meta.pop("normal_warning", None)  # a doubt about normals no method here reads
    mixed = feat.mixed(gaps, set(ref), set(buffers),
                       {b: ref[b].file.name for b in FEATURES if b in ref})
    said = "; ".join(filter(None, (mixed, feat.non_finite(buffers, files))))
    if said:
        meta["feature_warning"] = "; ".join(filter(None, (meta.get("feature_warning"), said)))
    meta.update(xl.layers_report(read.layers, info.path, info.ignored))
    meta["layers_ignored"] += feat.left_out_files(gaps, set(ref), slot)
    return Frame(color=color, stats=stats, meta=meta, **buffers)

