"""Write dbench frames as a folder that :mod:`dbench.datasets.folders.load` (and OIDN's tools) read.

The layout is OIDN's training-set layout with dbench's extra tags (docs/formats.md §1):

=================================  =========================================================
file                               content
=================================  =========================================================
``<name>_<spp:04d>.hdr.exr``       colour, channels ``R,G,B``
``<name>_<spp:04d>.alb.exr``       albedo, ``R,G,B``
``<name>_<spp:04d>.nrm.exr``       normal in [-1, 1] (signed, as OIDN stores them), ``R,G,B``
``<name>_<spp:04d>.pos.exr``       position, ``R,G,B``
``<name>_<spp:04d>.depth.exr``     depth, ``depth.Z`` (:func:`dbench.io.write_exr` naming)
``<name>_<spp:04d>.emitter.exr``   emitter coverage, ``emitter.Z``
``<name>_<spp:04d>.mv.exr``        motion, ``motion.c0``, ``motion.c1``
``<name>_<spp:04d>.stats.npz``     float64 ``n``, ``mean``, ``var_mean``, ``m3``, ``transform``,
                                   ``lam`` (and ``diagnostics`` as JSON text)
``<name>_ref.hdr.exr``             the reference, ``R,G,B``
``<name>_ref.var.exr``             σ² = reference_var · ref_spp, ``R,G,B`` (the variance of one
                                   sample, pbrt-v4's convention, so that the reader's division
                                   by ref_spp gives reference_var back)
``dataset.json``                   :func:`write_dataset_json`
=================================  =========================================================

The ``.stats.npz`` format is read here too (:func:`read_stats_npz`), so that one module owns
it. Three-channel files carry plain ``R,G,B``, what OIDN's scripts and image viewers read; the
others use dbench's own naming. ``<name>`` gains ``_f<frame:04d>`` for a frame of a sequence.
EXR holds float32 losslessly (ZIP), so buffers read back bit-identical; only the reference
variance goes through a float32 product and quotient (relative error below 1e-6).
Every write is atomic. ``gradient`` and ``emission`` have no place in the layout and are not
written.

Example:
    >>> export_frame(frame, "out/kitchen", "kitchen", 16)   # doctest: +SKIP
    >>> write_dataset_json("out/kitchen", ref_spp=4096, ev=0.0)   # doctest: +SKIP
"""
from __future__ import annotations

import json
import os
import zipfile
from pathlib import Path

import numpy as np

from ...data import Frame, SampleStats, check_count
from ...errors import DbenchInputError
from ...io import atomic_path, write_exr, write_json
from ...metrics.tonemapping import check_ev
from .exr_layers import write_channels

#: Frame buffer → file tag.
TAG_OF = {"albedo": "alb", "normal": "nrm", "position": "pos", "depth": "depth",
          "emitter": "emitter", "motion": "mv"}


def _rgb(path: Path, image: np.ndarray) -> None:
    write_channels(path, {c: image[..., i] for i, c in enumerate("RGB")})


def write_stats_npz(path: str | os.PathLike, stats: SampleStats) -> None:
    """Write ``stats`` as float64 arrays plus transform and λ, atomically."""
    with atomic_path(path, suffix=".tmp.npz") as tmp, open(tmp, "wb") as fh:
        np.savez(fh, n=stats.n, mean=stats.mean, var_mean=stats.var_mean, m3=stats.m3,
                 transform=np.array(stats.transform), lam=np.array(float(stats.lam)),
                 diagnostics=np.array(json.dumps(stats.diagnostics, default=int)))


def read_stats_npz(path: Path, shape: tuple[int, ...] | None = None, *,
                   settings_only: bool = False, spp: int | None = None):
    """The SampleStats in a ``.stats.npz`` (checked against ``shape`` when given), or only its
    (transform, λ) (reading no image arrays); a DbenchInputError naming the file when
    unreadable, or when ``spp`` (the count its name gives) is contradicted by a sample count
    the same at every pixel: such a file holds the statistics of other samples than the colour
    beside it (a copy of another spp's file), which no method could tell. A count that varies
    from pixel to pixel (adaptive sampling) is read as it is."""
    keys = {"n", "mean", "var_mean", "m3", "transform", "lam"}
    try:
        if not zipfile.is_zipfile(path):
            raise ValueError("not an .npz archive")
        with np.load(path, allow_pickle=False) as z:
            if keys - set(z.files):
                raise ValueError(f"lacks {sorted(keys - set(z.files))}; expected {sorted(keys)}")
            if settings_only:
                return str(z["transform"]), float(z["lam"])
            arrays = {k: z[k] for k in z.files}
        diagnostics = json.loads(str(arrays["diagnostics"])) if "diagnostics" in arrays else {}
        stats = SampleStats(n=arrays["n"], mean=arrays["mean"], var_mean=arrays["var_mean"],
                            m3=arrays["m3"], transform=str(arrays["transform"]),
                            lam=float(arrays["lam"]), diagnostics=diagnostics)
    except Exception as exc:  # noqa: BLE001 - bad zip, missing key, bad shape alike
        raise DbenchInputError(f"{path}: not a readable statistics file ({exc})") from None
    if shape is not None and stats.shape != tuple(shape):
        raise DbenchInputError(f"{path}: statistics of shape {stats.shape}; expected {shape}")
    n = np.asarray(stats.n)
    if spp is not None and n.size and (n == n.flat[0]).all() and float(n.flat[0]) != spp:
        raise DbenchInputError(f"{path}: statistics of {float(n.flat[0]):g} samples at every "
                               f"pixel in a file named for {spp} spp; expected n = {spp} "
                               f"(is it another spp's file?)")
    check_variance(stats.var_mean, f"{path}: var_mean", stats.mean)
    return stats


def check_variance(var: np.ndarray, where: str, values: np.ndarray | None = None) -> np.ndarray:
    """``var`` (a variance read from a file), refused naming ``where`` when a value is negative
    or NaN, except a NaN where ``values`` (the quantity it is the variance of, same shape) is
    itself not finite: read as it is, a negative variance would weigh a pixel as surer than
    certain and a NaN would spread through every method that reads it. +inf (a variance that
    overflowed, as dbench's own statistics count in ``n_nonfinite_moments``) says "unknown"
    and is read."""
    nan = np.isnan(var)
    if values is not None:
        nan &= np.isfinite(values)
    bad = nan | (var < 0)
    if bad.any():
        first = tuple(int(i) for i in np.argwhere(bad)[0])
        raise DbenchInputError(f"{where}: {int(bad.sum())} values negative or NaN (the first "
                               f"at {first}: {float(var[first])}); expected values >= 0 "
                               f"(+inf for unknown)")
    return var


def export_frame(frame: Frame, out_dir: str | os.PathLike, name: str, spp: int, *,
                 frame_index: int | None = None, write_reference: bool = True) -> list[Path]:
    """Write the buffers ``frame`` has into ``out_dir`` (table in the module docstring).

    Args:
        frame: a :class:`~dbench.data.Frame`; ``meta["ref_spp"]`` is needed when it carries
            ``reference_var``.
        out_dir: the folder (created when missing).
        name: view name, the prefix of every file; it must not contain a path separator.
        spp: the spp written into the noisy files' names.
        frame_index: frame number of a sequence frame (names get ``_f<frame:04d>``), or None.
        write_reference: also write the reference and its variance (when the frame has them).
    Returns:
        The paths written, in order.
    """
    if not isinstance(frame, Frame):
        raise DbenchInputError(f"frame: expected a Frame, got {type(frame).__name__}")
    if not name or os.sep in name or "/" in name:
        raise DbenchInputError(f"name: {name!r}; expected a non-empty view name without '/'")
    spp = check_count("spp", spp)
    out = Path(out_dir)
    base = name if frame_index is None else f"{name}_f{int(frame_index):04d}"
    noisy = f"{base}_{spp:04d}"
    written: list[Path] = []

    def put(path: Path, write, *args) -> None:
        write(path, *args)
        written.append(path)

    put(out / f"{noisy}.hdr.exr", _rgb, frame.color)
    for buffer, tag in TAG_OF.items():
        value = getattr(frame, buffer)
        if value is None:
            continue
        if value.shape[-1] == 3:
            put(out / f"{noisy}.{tag}.exr", _rgb, value)
        else:
            put(out / f"{noisy}.{tag}.exr", write_exr, {buffer: value})
    if frame.stats is not None:
        put(out / f"{noisy}.stats.npz", write_stats_npz, frame.stats)
    if write_reference and frame.reference is not None:
        put(out / f"{base}_ref.hdr.exr", _rgb, frame.reference)
        if frame.reference_var is not None:
            ref_spp = frame.meta.get("ref_spp")
            if ref_spp is None:
                raise DbenchInputError("frame.meta['ref_spp']: missing; needed to store "
                                       "reference_var as per-sample variance (σ² = var·ref_spp)")
            ref_spp = check_count("meta['ref_spp']", ref_spp)
            sigma2 = (frame.reference_var.astype(np.float64) * ref_spp).astype(np.float32)
            put(out / f"{base}_ref.var.exr", _rgb, sigma2)
    return written


def write_dataset_json(out_dir: str | os.PathLike, *, ref_spp: int | None, ev: float,
                       description: str = "", scene: str = "",
                       fingerprint: str | None = None) -> Path:
    """Write ``out_dir/dataset.json`` (ref_spp, ev, ``normal_encoding`` "signed" as README.md
    documents it, description, scene, and the exported scene's ``fingerprint`` where given:
    :func:`dbench.datasets.scene_fingerprint` at the exported size, which
    :func:`check_export_folder` compares before more spp are added)."""
    if ref_spp is not None:
        ref_spp = check_count("ref_spp", ref_spp)
    path = Path(out_dir) / "dataset.json"
    write_json(path, {"ref_spp": ref_spp, "ev": float(ev), "normal_encoding": "signed",
                      "description": str(description), "scene": str(scene),
                      **({"fingerprint": str(fingerprint)} if fingerprint else {})})
    return path


def read_dataset_json(folder: Path) -> dict:
    """``folder/dataset.json`` checked (README.md, "Your scene, your renders, any size"), or {} where there is
    none; a file of the wrong shape is refused, naming the key."""
    path = folder / "dataset.json"
    if not path.exists():
        return {}
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise DbenchInputError(f"{path}: not readable JSON ({exc})") from None
    kinds = {"ref_spp": int, "ev": (int, float), "normal_encoding": str, "normals": str,
             "description": str, "scene": str, "fingerprint": str}
    if not isinstance(data, dict):
        raise DbenchInputError(f"{path}: expected a JSON object with keys {sorted(kinds)}")
    for key, value in data.items():
        if key in kinds and value is not None and (not isinstance(value, kinds[key])
                                                   or isinstance(value, bool)):
            raise DbenchInputError(f"{path}: {key!r} has the wrong type ({value!r})")
    for key in ("normal_encoding", "normals"):  # "normals": the exporter's spelling
        if data.get(key) not in (None, "signed", "unsigned"):
            raise DbenchInputError(f"{path}: {key} {data[key]!r}; expected \"signed\" or "
                                   "\"unsigned\"")
    if None not in (data.get("normal_encoding"), data.get("normals")) \
            and data["normal_encoding"] != data["normals"]:
        raise DbenchInputError(f"{path}: normal_encoding {data['normal_encoding']!r} and "
                               f"normals {data['normals']!r} disagree; expected one")
    if data.get("ref_spp") is not None and data["ref_spp"] < 1:
        raise DbenchInputError(f"{path}: ref_spp {data['ref_spp']}; expected an integer >= 1")
    if data.get("ev") is not None:
        # JSON's NaN, Infinity or 1e6 failed only in the metrics, after every method ran
        try:
            check_ev(data["ev"])
        except DbenchInputError as exc:
            raise DbenchInputError(f"{path}: {exc}") from None
    return data


def check_export_folder(out: Path, *, scene: str, ref_spp: int | None, ev: float,
                        fingerprint: str | None = None) -> None:
    """Refuse an ``out`` that holds other files than an export of ``scene`` with the same
    reference spp (None: no reference), exposure and ``fingerprint`` (the scene's content,
    parameters, size and renderer; :func:`write_dataset_json`): its ``dataset.json`` (one per
    folder) would be rewritten for this scene, mis-describing the renders already there, and
    files of other tools would mix with these. The name alone let an edited scene file, other
    ``--scene-param`` values or another ``--res`` add spp beside renders of another scene, and
    overwrite their reference."""
    out = Path(out)
    if not out.is_dir() or not any(out.iterdir()):
        return
    old = read_dataset_json(out) if (out / "dataset.json").is_file() else {}
    if not old:
        raise DbenchInputError(f"--out {out}: a folder holding other files and no export's "
                               f"dataset.json; export into a new or empty folder")
    want = {"scene": scene, "ref_spp": ref_spp, "ev": float(ev)}
    for key, value in want.items():
        if old.get(key) != value:
            raise DbenchInputError(f"--out {out}: holds an export with {key} {old.get(key)!r}, "
                                   f"not {value!r}; export into a new or empty folder (one "
                                   f"dataset.json describes the whole folder)")
    if fingerprint is not None and old.get("fingerprint") != fingerprint:
        # (an export without one, an older dbench's, cannot be shown to be the same scene)
        held = repr(old["fingerprint"]) if old.get("fingerprint") else "none recorded"
        raise DbenchInputError(f"--out {out}: holds an export of {scene} with fingerprint "
                               f"{held}, not {fingerprint!r} (other content, --scene-param "
                               f"values, --res or renderer); export into a new or empty "
                               f"folder (one dataset.json describes the whole folder)")
