"""The frame a method receives: its own read-only copy, compared with the original after the
method's calls (README "Add your own denoiser": ``denoise`` must not modify its input).

A method that writes to its input (``data.color *= 0``) would otherwise change the numbers of
every method after it, the noisy baseline included. Each method therefore gets a private copy
whose arrays are read-only (a NumPy write raises at once), and after its calls the copy is
compared byte for byte with the original (a write through another route, e.g. a tensor made
from the array with ``torch.from_numpy``, is caught there). Either way the method fails with a
:class:`MethodError` naming it and the buffer, and the other methods still receive the pristine
frame. The copy is made outside the timed calls.

What it gives back: :func:`check_output` refuses what is no radiance of the input's shape;
:func:`output_difference` compares two outputs of one input (the harness's first call and
each later one, a sequence's warm-up and first frames), which a deterministic method gives
equal; :func:`merge_difference` keeps the largest of several.

:func:`load_seeds` gives the frames themselves: one per seed of a cell, for ``run``, ``sweep``
and the sweep's checks before it writes anything; :func:`input_notes` what the loaded input
says of itself (a folder's facts, the doubts of :data:`INPUT_WARNINGS`).
"""
from __future__ import annotations

import copy
import sys
from contextlib import contextmanager
from typing import Any

import numpy as np

#: Array attributes of Frame / TransientFrame (``stats`` is handled apart).
_SKIP = {"meta", "kind"}
#: What a method's copy leaves out: the ground truth it is scored against (a method that read
#: ``data.reference`` scored a perfect 0 error without a word).
#: README.md "Add your own denoiser" says so.
HIDDEN = ("reference", "reference_var")
_STATS = ("n", "mean", "var_mean", "m3")


class MethodError(Exception):
    """A method failed or broke the method contract; the message names the method."""


def method_failure(exc: BaseException) -> str:
    """One line for a method's failure (``dbench run``'s stderr and report, a sweep's error
    cell, ``dbench bench``): the harness's own message for a broken contract, else the
    exception's type and message; a message over several lines is joined into one (README.md
    "Usage": a refusal or a failure is one line)."""
    if isinstance(exc, MethodError):
        text = str(exc)
    elif isinstance(exc, SystemExit):
        text = f"called sys.exit({exc.code!r}) inside the method"
    else:
        text = f"{type(exc).__name__}: {exc}"
    return " ".join(text.split())


def check_output(method_name: str, output: Any, shape: tuple) -> np.ndarray:
    """``output`` as an array, refused (DbenchInputError naming the method) unless it holds
    floating-point numbers in ``shape``, the input colour's (README.md "Add your own denoiser": float32
    of the shape of ``data.color``): None, a wrong shape, complex, object or string values
    (which would otherwise fail inside the metrics with an error of NumPy's), and integers or
    booleans (radiance truncated to whole numbers: scored, they only looked like a bad method,
    and ``dbench stress`` already failed them)."""
    from ..errors import DbenchInputError

    out = np.asarray(output)
    if output is None or out.shape != tuple(shape):
        raise DbenchInputError(f"{method_name} output: expected shape {tuple(shape)}, got "
                               f"{'None' if output is None else out.shape}")
    if out.dtype.kind != "f":
        raise DbenchInputError(f"{method_name} output: expected floating-point radiance "
                               f"(float32), got dtype {out.dtype}")
    return out


def output_copy(output: Any) -> Any:
    """A copy of a method's output that later calls cannot change: a tensor's on its device,
    else a NumPy array (None where the output is no array: the last call's is checked)."""
    if hasattr(output, "detach") and hasattr(output, "clone"):
        return output.detach().clone()
    try:
        return np.array(output, copy=True)
    except (TypeError, ValueError):
        return None


def output_difference(first: Any, last: Any) -> dict[str, float] | None:
    """None where two outputs of one input are equal (``np.array_equal``; NaN in the same
    places counts as equal), else the largest absolute difference ``max_abs_diff`` and that
    over the largest |value| of ``last``, ``max_rel_diff`` (README.md, "Usage": a method
    whose calls differ is flagged, never passed over). A value finite in one output and not
    in the other, or outputs of different shapes, differ by ``inf``."""
    a, b = np.asarray(first), np.asarray(last)
    numeric = a.dtype.kind in "biuf" and b.dtype.kind in "biuf"
    if a.shape == b.shape and numeric and np.array_equal(
            a, b, equal_nan=a.dtype.kind == "f" or b.dtype.kind == "f"):
        return None
    if a.shape != b.shape or not numeric:
        return {"max_abs_diff": float("inf"), "max_rel_diff": float("inf")}
    a64, b64 = a.astype(np.float64), b.astype(np.float64)
    both = np.isfinite(a64) & np.isfinite(b64)
    same_nan = np.isnan(a64) & np.isnan(b64)
    with np.errstate(invalid="ignore", over="ignore"):
        diff = np.where(both, np.abs(a64 - b64), 0.0)
        # ±inf against a number, NaN against a number or +inf against -inf
        apart = ~both & ~same_nan & ~(a64 == b64)
    largest = float("inf") if apart.any() else float(diff.max())
    scale = float(np.abs(b64[np.isfinite(b64)]).max()) if np.isfinite(b64).any() else 0.0
    return {"max_abs_diff": largest,
            "max_rel_diff": largest / scale if scale > 0 else float("inf")}


#: The keys of an :func:`output_difference` that :func:`merge_difference` keeps the largest of.
DIFFERENCE_KEYS = ("max_abs_diff", "max_rel_diff")


def merge_difference(found: dict[str, Any], diff: dict[str, Any] | None) -> dict[str, Any]:
    """``found`` (a dict, left unchanged) with the larger of its and ``diff``'s
    ``max_abs_diff`` and ``max_rel_diff`` (:func:`output_difference`; a key ``found`` lacks
    counts as 0): the largest difference over several compared outputs (calls, seeds,
    frames). Its other keys are kept; ``diff`` None (equal outputs) changes nothing."""
    if diff is None:
        return dict(found)
    return {**found, **{k: max(found.get(k, 0.0), diff[k]) for k in DIFFERENCE_KEYS
                        if k in diff}}


def _arrays(obj: Any) -> dict[str, np.ndarray]:
    return {k: v for k, v in vars(obj).items() if isinstance(v, np.ndarray) and k not in _SKIP}


def _frozen(a: np.ndarray, writeable: bool = False) -> np.ndarray:
    c = np.array(a, copy=True)
    c.flags.writeable = writeable
    return c


def private_copy(frame: Any, writeable: bool = False) -> Any:
    """A shallow copy of ``frame`` (a Frame or TransientFrame; a Sequence frame by frame) whose
    arrays, the statistics' included, are read-only copies (``writeable``: copies that can be
    written, to find which one a method writes to: :func:`input_guard`), and which holds no
    reference (:data:`HIDDEN`: None there)."""
    if hasattr(frame, "frames"):
        out = copy.copy(frame)
        out.frames = [private_copy(f, writeable) for f in frame.frames]
        return out
    out = copy.copy(frame)
    for k, v in _arrays(frame).items():
        setattr(out, k, None if k in HIDDEN else _frozen(v, writeable))
    st = getattr(frame, "stats", None)
    if st is not None:
        st2 = copy.copy(st)
        for k in _STATS:
            setattr(st2, k, _frozen(getattr(st, k), writeable))
        out.stats = st2
    return out


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and a.dtype == b.dtype and (
        np.ascontiguousarray(a).tobytes() == np.ascontiguousarray(b).tobytes())


def first_changed(copied: Any, original: Any) -> str | None:
    """The name of the first buffer whose bytes differ between ``copied`` and ``original``
    (``stats.mean`` for statistics; ``frame 3: color`` in a sequence), else None."""
    if hasattr(original, "frames"):
        for i, (a, b) in enumerate(zip(copied.frames, original.frames)):
            name = first_changed(a, b)
            if name:
                return f"frame {i}: {name}"
        return None
    for k, v in _arrays(original).items():
        mine = getattr(copied, k)
        if k in HIDDEN and mine is None:  # left out of the method's copy
            continue
        if not isinstance(mine, np.ndarray) or not _same(mine, v):
            return k
    st = getattr(original, "stats", None)
    if st is not None:
        for k in _STATS:
            if not _same(getattr(copied.stats, k), getattr(st, k)):
                return f"stats.{k}"
    return None


def check_unchanged(method_name: str, copied: Any, original: Any) -> None:
    """Raise :class:`MethodError` when ``method_name`` changed its copy of the input."""
    name = first_changed(copied, original)
    if name:
        raise MethodError(f"{method_name}: modified its input buffer {name} (a method must "
                          "not write to its input; the other methods got the unmodified frame)")


def is_write_to_input(exc: BaseException) -> bool:
    """Whether ``exc`` is NumPy's refusal to write to a read-only array."""
    return isinstance(exc, ValueError) and "read-only" in str(exc)


@contextmanager
def input_guard(method_name: str, original: Any = None, rerun=None):
    """Turn NumPy's refusal to write to the read-only input into a :class:`MethodError` naming
    the method and, with ``original`` (the frame) and ``rerun`` (a call of the method on a
    frame), the buffer: the method runs once more on a copy that can be written, and the
    buffer whose bytes then differ is named; every other exception passes unchanged."""
    try:
        yield
    except ValueError as exc:
        if not is_write_to_input(exc):
            raise
        name = None
        if original is not None and rerun is not None:
            spare = private_copy(original, writeable=True)
            try:
                rerun(spare)
            except Exception:  # noqa: BLE001 - only which buffer it wrote to is wanted here
                pass
            name = first_changed(spare, original)
        what = f"its input buffer {name}" if name else "its input"
        raise MethodError(f"{method_name}: modified {what} (wrote to a read-only input array: "
                          f"{exc}); a method must not write to its input") from exc


def load_seeds(scene, seed: int, n_seeds: int, **load_kwargs) -> list:
    """One frame (or sequence) per seed ``seed`` … ``seed + n_seeds − 1``, all scored against
    the one reference of ``seed`` (shared by ``run`` and ``sweep``); ``load_kwargs`` go to
    :func:`dbench.datasets.load`."""
    from .. import datasets

    frames = [datasets.load(scene, seed=seed + k, ref_seed=seed, **load_kwargs)
              for k in range(n_seeds)]
    check_reference_lit(frames[0], getattr(scene, "name", scene))
    note_noise_free(frames)
    return frames


def check_reference_lit(data: Any, scene_name: str) -> None:
    """Refuse ``data`` (a Frame, Sequence or TransientFrame) whose reference is 0 in every
    pixel (and frame, and bin): emitters of zero radiance, or lights that reach nothing the
    camera sees. Every method would then score 0 error on it, and rank as a tie, which is no
    finding (README.md, "Metrics"); a scene without any emitter is
    refused before rendering (:func:`dbench.datasets.scenes.build.check_lit`)."""
    from ..errors import DbenchInputError

    frames = data.frames if getattr(data, "kind", "") == "sequence" else [data]
    refs = [f.reference for f in frames if getattr(f, "reference", None) is not None]
    if refs and not any(np.any(r) for r in refs):
        video = getattr(data, "kind", "") == "transient"
        where = " and frame" if len(frames) > 1 else " and time bin" if video else ""
        when = " within the video's time window" if video else ""
        raise DbenchInputError(
            f"scene {scene_name}: the reference is 0 in every pixel{where} (no light of its "
            f"emitters reaches the camera{when}), so every method would score a perfect 0 "
            f"error; give a light some radiance or point the camera at what it lights")


def _frame_noise_free(frame: Any) -> bool:
    """Whether one rendered Frame or TransientFrame has nothing to denoise: its noisy image
    equals its reference exactly (independent renders, with other seeds) and every variance it
    holds of its samples is 0 (:func:`noise_free`)."""
    ref = getattr(frame, "reference", None)
    if ref is None or not np.array_equal(frame.color, ref):
        return False
    stats = getattr(frame, "stats", None)
    held = (getattr(frame, "reference_var", None), getattr(frame, "total_var", None),
            None if stats is None else stats.var_mean)
    return not any(v is not None and np.any(v) for v in held)


def noise_free(data: Any) -> bool:
    """Whether the rendered input ``data`` (a Frame, TransientFrame or Sequence) has no sample
    variance at all: at every pixel (of every frame, in every time bin) its noisy image equals
    the reference exactly, and every per-pixel variance dbench holds of the scene's samples is
    0 there: the reference's chunk spread (``reference_var``), the noisy samples' statistics
    where they were gathered (``stats.var_mean``, docs/methods/statistical.md §4.1: σ² is 0
    where the samples are all one value), a transient video's totals (``total_var``). The two
    renders use other seeds, so they agree bit for bit only where every sample of a pixel is
    the same value (a constant environment seen directly, an emitter filling the view).
    A pixel or frame with any noise makes it False: most pixels noise-free is normal (README.md,
    "How renders work"). A folder of renders is never judged here: its reference has no
    samples of dbench's, and one equal to a noisy image is already said
    (``reference_warning``, dbench/datasets/folders/reference.py)."""
    frames = data.frames if getattr(data, "kind", "") == "sequence" else [data]
    if not frames or any(f.meta.get("source") == "folder" for f in frames):
        return False
    return all(_frame_noise_free(f) for f in frames)


def noise_free_text(data: Any) -> str:
    """The warning of an input with nothing to denoise (:func:`noise_free`), one line."""
    kind = getattr(data, "kind", "")
    where = (" in every frame" if kind == "sequence" else " and time bin"
             if kind == "transient" else "")
    return (f"the noisy image has no sample variance (it equals its expected value, the "
            f"reference, at every pixel{where}): there is nothing to denoise, the noisy input "
            f"scores 0 error and a method's error is only what it changes of an exact image; "
            f"rankings at this spp carry no information")


def note_noise_free(frames: list) -> None:
    """Adds ``noise_free_warning`` (one of :data:`INPUT_WARNINGS`) to the meta of every loaded
    seed of ``frames`` (a sequence's own meta) when each has nothing to denoise
    (:func:`noise_free`): ``dbench run`` prints it and a sweep records it in its cells, as
    every warning of the input."""
    if frames and all(noise_free(d) for d in frames):
        for d in frames:
            d.meta["noise_free_warning"] = noise_free_text(d)


#: input facts a folder load reports (dbench/datasets/folders/load.py): {meta key: settings label}
INPUT_FACTS = {"ref_noise_source": "reference noise from", "surface_pixels": "surface pixels",
                "normal_encoding": "normal encoding", "layers_read": "layers read",
                "layers_ignored": "layers ignored"}
#: doubts about the input: printed at once and listed in the report's notes
INPUT_WARNINGS = ("noise_free_warning", "reference_warning", "normal_warning", "feature_warning",
                  "nonfinite_warning")


def input_metas(data: Any) -> tuple[list[dict], dict | None]:
    """What :func:`input_notes` reads of a loaded input: (every frame's meta, the sequence's
    own) of a Sequence, ([its meta], None) of a Frame or TransientFrame."""
    if getattr(data, "kind", "") == "sequence":
        return [f.meta for f in data], data.meta
    return [data.meta], None


def _by_value(metas: list[dict], key: str) -> list[tuple[str, list[int]]]:
    """[(the value of ``key`` as text, the frames that hold it)] over ``metas``."""
    found: dict[str, list[int]] = {}
    for k, meta in enumerate(metas):
        value = meta.get(key)
        if value:
            text = "; ".join(value) if isinstance(value, (list, tuple)) else str(value)
            found.setdefault(text, []).append(k)
    return list(found.items())


def warning_lines(metas: list[dict], whole: dict | None = None) -> list[str]:
    """The warnings of :data:`INPUT_WARNINGS` a loaded input carries (``metas`` and ``whole`` as
    for :func:`input_notes`), one line each: a warning that differs between frames with the
    frames it holds for ("frames 0-3: …"), one the frames share once; a sequence's own
    (``whole``: a rendered sequence's non-finite samples, summed over its frames,
    dbench/datasets/nonfinite.py) first, where its frames do not carry it."""
    notes = [whole[key] for key in INPUT_WARNINGS if (whole or {}).get(key)
             and not any(meta.get(key) for meta in metas)]
    for key in INPUT_WARNINGS:
        for value, ks in _by_value(metas, key):
            notes.append(value if len(ks) == len(metas) else f"{frames_text(ks)}: {value}")
    return notes


def input_warnings(data: Any) -> list[str]:
    """:func:`warning_lines` of a loaded input (a Frame, TransientFrame or Sequence): what
    ``dbench run`` prints of it and a sweep records in each of its cells (``input_warnings``)."""
    return warning_lines(*input_metas(data))


def input_notes(metas: list[dict], settings: dict, whole: dict | None = None) -> list[str]:
    """Adds a loaded input's facts to ``settings`` and returns its warnings
    (:func:`warning_lines`), each also printed to stderr now: a doubtful reference or normal
    buffer is said where the user looks. ``metas``: one frame's meta, or every frame's of a
    sequence (a folder's facts are found frame by frame): a fact that differs between frames
    is given with the frames it holds for ("frames 0-3: …; frame 4: …"), one the frames share
    once. ``whole``: a sequence's own meta (:func:`input_metas`)."""
    for key, label in INPUT_FACTS.items():
        values = _by_value(metas, key)
        if len(values) == 1 and len(values[0][1]) == len(metas):
            settings[label] = values[0][0]
        elif values:
            settings[label] = "; ".join(f"{frames_text(ks)}: {v}" for v, ks in values)
    notes = warning_lines(metas, whole)
    for note in notes:
        print(f"warning: {note}", file=sys.stderr)
    return notes


def frames_text(ks: list[int], word: str = "frame") -> str:
    """``frame 4``, ``frames 0-3``, ``frames 0, 2, 5`` (``word``: ``call 2``, ``calls 2-3``)."""
    if len(ks) == 1:
        return f"{word} {ks[0]}"
    if ks == list(range(ks[0], ks[-1] + 1)):
        return f"{word}s {ks[0]}-{ks[-1]}"
    return f"{word}s " + ", ".join(map(str, ks))


__all__ = ["MethodError", "check_output", "output_copy", "output_difference", "method_failure",
           "DIFFERENCE_KEYS", "merge_difference",
           "load_seeds", "check_reference_lit",
           "noise_free", "noise_free_text", "note_noise_free",
           "check_unchanged", "first_changed", "input_guard", "is_write_to_input", "private_copy",
           "INPUT_FACTS", "INPUT_WARNINGS", "input_metas", "input_notes", "input_warnings",
           "warning_lines", "frames_text"]
