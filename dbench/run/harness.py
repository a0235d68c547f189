"""One benchmark cell: a method run on a dataset, timed, and scored against the reference, and
the record of its numbers that ``run`` and ``sweep`` write (:func:`cell_record`).

Timing (README "Usage"): rendering and I/O are excluded; one warm-up call, then the
median of ``repeats`` calls measured with ``time.perf_counter``. On a GPU (``device="cuda"``) a
method with a device path (``Denoiser.runs_on_device``) gets its frame uploaded once, is timed
with the device synchronised before and after each call, and its output is brought back once;
the copies are timed apart (``transfer_s``) and never counted as the method's time. A method
without a device path runs on the host and its cell says so (``device="cpu"``), so CPU and GPU
figures are never mixed under one label (docs/gpu.md §3).

The last call is scored. A copy of the first call's output (the warm-up's) is kept, and every
later call's output is compared with it, untimed: where any differs (``np.array_equal``, NaN in
the same places equal; no tolerance), the cell records ``nondeterministic`` (the largest
difference, and which calls differed) and ``dbench run`` and the reports say its numbers are
those of one call and not reproducible (README.md, "Usage").
"""
from __future__ import annotations

import statistics
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from ..metrics import judge
from ..errors import DbenchInputError
from ..registry import Denoiser, applies
from ..device import device_name, download, timed, upload
from . import fpenv
from .machine import machine_label
from .inputs import (check_output, check_unchanged, frames_text, input_guard,
                     merge_difference, output_copy, output_difference, private_copy)
from .scoring import DEFAULT_METRICS, judge_frame
from .sequence_run import WARMUP, after_warmup, run_sequence


@dataclass
class CellResult:
    """Outcome of one (method, dataset) cell, over one or several seeds.

    ``metrics`` holds, for every judged column (:func:`dbench.metrics.judge.metric_names`), the
    mean over seeds and ``<column>_ci``, the half-width of its 95 % interval (Student t over
    seeds, or a block bootstrap with one seed: ``ci_kind`` says which), plus ``ref_rmse``.
    ``per_seed`` holds one row of values per seed; ``output`` is the first seed's output.
    """

    method: str
    params: dict[str, Any]
    output: np.ndarray | None
    metrics: dict[str, float] = field(default_factory=dict)
    times_s: list[float] = field(default_factory=list)
    skipped: str = ""
    n_nonfinite: int = 0
    sequence: Any = None  # the SequenceResult of a sequence cell (first seed)
    per_seed: list[dict[str, Any]] = field(default_factory=list)
    ci_kind: str = ""
    #: what the method resolved on the first seed (its ``last_settings``: e.g. the statistical
    #: denoiser's γ_t, ν, base filter and automatic temporal radius), scalars only
    settings: dict[str, Any] = field(default_factory=dict)
    #: where the method ran ("cpu" or "cuda"), that device's name and the method's backend
    device: str = "cpu"
    device_name: str = "cpu"
    backend: str = ""
    #: seconds of host→device upload plus device→host download per seed (device cells only)
    transfer_s: list[float] = field(default_factory=list)
    #: where calls on one input gave different outputs: the seeds, the largest ``max_abs_diff``
    #: and ``max_rel_diff`` (:func:`output_difference`) and the calls that differed from the
    #: first, as text; {} where none did
    nondeterministic: dict[str, Any] = field(default_factory=dict)

    @property
    def time_s(self) -> float:
        return statistics.median(self.times_s) if self.times_s else float("nan")

    @property
    def time_s_iqr(self) -> float:
        """Interquartile range of the timed calls; NaN with fewer than two (one call gives no
        spread, and a "± 0" would read as an exact time)."""
        if len(self.times_s) < 2:
            return float("nan")
        q1, q3 = np.percentile(self.times_s, [25, 75])
        return float(q3 - q1)

    @property
    def n_seeds(self) -> int:
        return max(1, len(self.per_seed))


def resolved_settings(method: Denoiser) -> dict[str, Any]:
    """The scalar entries of a method's ``last_settings`` after a call (numbers, strings,
    booleans, None, and short lists or tuples of them), as plain Python values; arrays and
    nested objects are left out. {} for a method that records none; a ``last_settings`` that is
    no dict breaks the method contract (README.md "Add your own denoiser") and fails the
    method with that said, not with an AttributeError of dbench's."""
    from .inputs import MethodError

    settings = getattr(method, "last_settings", None) or {}
    if not isinstance(settings, dict):
        raise MethodError(f"{method.name}: last_settings is a {type(settings).__name__}; "
                          f"expected a dict of setting names and values")
    out: dict[str, Any] = {}
    for key, value in settings.items():
        if isinstance(value, np.generic):
            value = value.item()
        if isinstance(value, (list, tuple)) and len(value) <= 16 and all(
                isinstance(v, (bool, int, float, str, type(None), np.generic)) for v in value):
            value = [v.item() if isinstance(v, np.generic) else v for v in value]
        elif not isinstance(value, (bool, int, float, str, type(None))):
            continue
        out[str(key)] = value
    return out


def time_call(fn, repeats: int = 5, warmup: int = 1, device: str = "cpu"
              ) -> tuple[Any, list[float]]:
    """Call ``fn()`` ``warmup`` times, then ``repeats`` times; return the last result and times
    (each call timed with ``device`` synchronised before and after it)."""
    result, times, _ = timed_calls(fn, repeats, warmup, device)
    return result, times


def timed_calls(fn, repeats: int = 5, warmup: int = 1, device: str = "cpu", keep=None,
                differ=output_difference) -> tuple[Any, list[float], dict[str, Any]]:
    """:func:`time_call`, and with ``keep`` every call's output compared with the first's:
    ``keep(first result)`` is a copy of it that later calls cannot overwrite (None: nothing to
    compare), and ``differ(copy, result)`` (:func:`output_difference`) compares each later
    call's result with it. Both run outside the timed interval, and only that one copy and the
    running largest difference are kept, never every output (a method whose calls alternate
    A, B, A is caught, which comparing only the first and the last would pass over).

    Returns (the last result, the times, what differed): {} where every call gave the first's
    output (or with one call, or without ``keep``), else the largest ``max_abs_diff`` and
    ``max_rel_diff`` over the calls (:func:`merge_difference`), ``calls``, the numbers of the
    calls that differed (1 is the first, the warm-up counted), and ``of``, how many ran."""
    first = result = None
    found: dict[str, Any] = {}
    times: list[float] = []
    total = warmup + max(1, repeats)
    for call in range(1, total + 1):
        if call <= warmup:
            result = fn()
        else:
            result, dt = timed(fn, device)
            times.append(dt)
        if keep is None:
            continue
        if call == 1:
            first = keep(result)
        elif first is not None:
            diff = differ(first, result)
            if diff is not None:
                found = merge_difference(found, diff)
                found.setdefault("calls", []).append(call)
    return result, times, ({**found, "of": total} if found else {})


def note_difference(result: CellResult, seed: Any, diff: dict[str, float] | None,
                    calls: str, scored: str = "the last call") -> None:
    """Adds one seed's :func:`output_difference` (or the largest over its calls) to
    ``result.nondeterministic``: the seeds whose calls differed, the largest differences over
    them (:func:`merge_difference`), which calls differed (``calls``, text) and which were
    ``scored``."""
    if diff is None:
        return
    nd = result.nondeterministic
    nd.setdefault("seeds", []).append(seed.item() if isinstance(seed, np.generic) else seed)
    nd.update(merge_difference(nd, diff), calls=calls, scored=scored)


def method_backend(method: Denoiser, on_device: bool) -> str:
    """The backend a cell records: the device path's, or the resolved host ``backend``
    parameter (its ``last_settings`` entry when the method resolved "auto"), else "python"."""
    if on_device:
        return method.device_backend or "device"
    settings = getattr(method, "last_settings", None) or {}
    value = settings.get("backend", method.params.get("backend", ""))
    return str(value) if value else "python"


def placement(method: Denoiser, device: str) -> tuple[bool, str]:
    """(runs on the device, the device it runs on) for ``method`` asked to run on ``device``."""
    on_device = device != "cpu" and method.runs_on_device()
    return on_device, (device if on_device else "cpu")


def summarise_seeds(per_seed: list[dict[str, Any]], judgements: list[list],
                    columns: Sequence[str]) -> tuple[dict[str, float], str]:
    """(metrics with ``_ci``, ci_kind): Student t over seeds, or with one seed the block
    bootstrap of its judgements (a list of per-frame Judgements for that seed)."""
    if len(per_seed) >= 2:
        out = judge.interval_over_seeds(per_seed, columns)
    else:
        out = {c: per_seed[0].get(c, float("nan")) for c in columns}
        out.update(judge.bootstrap_interval(judgements[0], columns))
    out["ref_rmse"] = per_seed[0].get("ref_rmse", float("nan"))
    out["ref_relmse_surface"] = per_seed[0].get("ref_relmse_surface", float("nan"))
    block = judge.block_of(judgements[0]) if judgements else None
    return out, judge.ci_kind(len(per_seed), block)


def _buffers(frame) -> set[str]:
    from ..data import BUFFER_NAMES
    return {b for b in BUFFER_NAMES if getattr(frame, b, None) is not None}


def _as_list(frames) -> list:
    return list(frames) if isinstance(frames, (list, tuple)) else [frames]


def check_cell_args(method: Any, frames: list, metric_names: Any, repeats: int | None,
                    warmup: int | None, extra: tuple = ()) -> None:
    """Refuse, naming the argument, what :func:`run_cell` and :func:`run_sequence_cell` would
    otherwise coerce or drop without a word: a method that is not built (a name), no frames,
    frames that differ in size (or, for steady frames, in reference: one cell's seeds share
    one), metric names that are no judged metric (or a string, which reads as its letters),
    repeats below 1 and a negative warm-up (``None``: not an argument of the caller)."""
    from ..data import check_count

    if not isinstance(method, Denoiser):
        raise DbenchInputError(f"method: expected a built method (dbench.registry.get(name)), "
                               f"got {method!r}")
    if not frames:
        raise DbenchInputError("frame: expected a frame or a non-empty list of them (one per "
                               "seed)")
    # a steady or transient frame has its colour; a sequence its frames
    shapes = {(np.shape(f.color), 0) if hasattr(f, "color") else (np.shape(f[0].color), len(f))
              for f in frames}
    refs = [getattr(f, "reference", None) if hasattr(f, "color") else None for f in frames]
    if len(shapes) > 1 or (refs[0] is not None and any(
            r is None or not np.array_equal(r, refs[0]) for r in refs[1:])):
        raise DbenchInputError("frame: the frames of one cell (one per seed) must have one "
                               "size (and length) and share one reference")
    valid = list(judge.JUDGED) + list(extra)
    if isinstance(metric_names, (str, bytes)) or any(n not in valid for n in metric_names):
        raise DbenchInputError(f"metric_names: expected a list of judged metrics, got "
                               f"{metric_names!r}; valid: {valid}")
    if repeats is not None:
        check_count("repeats", repeats)
    if warmup is not None and (isinstance(warmup, bool) or not isinstance(
            warmup, (int, np.integer)) or warmup < 0):
        raise DbenchInputError(f"warmup: expected an integer >= 0, got {warmup!r}")


def run_cell(method: Denoiser, frame, metric_names=DEFAULT_METRICS, repeats: int = 5,
             warmup: int = 1, device: str = "cpu") -> CellResult:
    """Run ``method`` on ``frame`` (or a list of frames, one per seed, sharing one reference);
    skip with a reason when it does not apply.

    Each seed is timed alone (``warmup`` calls, then ``repeats``); ``times_s`` pools the timed
    calls of every seed. Metrics: see :class:`CellResult`; they score the last call, and where
    any call's output differs from the first's (:func:`timed_calls`), ``nondeterministic``
    says so.
    """
    frames = _as_list(frame)
    check_cell_args(method, frames, metric_names, repeats, warmup)
    first = frames[0]
    available = _buffers(first)
    ok, reason = applies(method, getattr(first, "kind", "steady"), available)
    if not ok:
        return CellResult(method.name, dict(method.params), None, skipped=reason)
    columns = judge.metric_names([n for n in metric_names if n in judge.JUDGED])
    on_device, where = placement(method, device)
    result = CellResult(method.name, dict(method.params), None, device=where,
                        device_name=device_name(where))
    judgements = []
    differed: set[int] = set()  # the calls whose output differed from the first's, any seed
    for i, f in enumerate(frames):
        mine = private_copy(f)  # read-only; compared with f after the calls (run/inputs.py)
        if on_device:
            data, up_s = timed(lambda: upload(mine, where, method.wants(_buffers(mine))), where)

            def call(data=data):
                method.reset()
                return fpenv.denoise_device(method, data)
        else:
            def call(mine=mine):
                method.reset()
                return fpenv.denoise(method, mine)

        def rerun(spare):  # finds the buffer a write to the read-only copy aimed at
            method.reset()
            return fpenv.denoise(method, spare)

        with input_guard(method.name, None if on_device else f, rerun):
            # every call after the first (the warm-up) against it, on the host
            output, times, apart = timed_calls(
                call, repeats, warmup, where,
                keep=(lambda out: output_copy(download(out))) if on_device else output_copy,
                differ=(lambda kept, out: output_difference(kept, download(out)))
                if on_device else output_difference)
        check_unchanged(method.name, mine, f)
        if on_device:
            output, down_s = timed(lambda out=output: download(out), where)
            result.transfer_s.append(up_s + down_s)
        output = check_output(method.name, output, f.color.shape)
        if apart:
            differed.update(apart["calls"])  # over the seeds so far
            note_difference(result, f.meta.get("seed", i), apart,
                            f"{frames_text(sorted(differed), 'call')} of {apart['of']} "
                            "differed from the first")
        result.times_s += times
        result.n_nonfinite += int((~np.isfinite(output)).sum())
        if result.output is None:
            result.output = output.astype(np.float32)
            result.settings = resolved_settings(method)
            result.backend = method_backend(method, on_device)
        if f.reference is not None:
            j = judge_frame(output, f, metric_names)
            judgements.append([j])
            result.per_seed.append({"seed": f.meta.get("seed", i), **j.values})
    if result.per_seed:
        result.metrics, result.ci_kind = summarise_seeds(result.per_seed, judgements, columns)
    return result


def run_sequence_cell(method: Denoiser, seq, metric_names=DEFAULT_METRICS,
                      warmup: int | None = None, device: str = "cpu",
                      cvvdp: bool | None = None) -> CellResult:
    """Run a temporal ``method`` over a :class:`~dbench.data.Sequence` (or a list of them, one
    per seed): ``reset()`` once, then every frame in order, and summarise it as one cell.

    A recurrent method cannot be re-run on a frame, so each frame is timed once:
    ``times_s`` are the per-frame times after the warm-up (``time_s`` is their median) and the
    metrics are means over those frames (dbench.run.sequence_run, docs/methods/svgf.md §8), plus the
    temporal stability ``t_rmse`` and ``tpsnr`` and ColorVideoVDP's ``cvvdp`` (JOD, higher is
    better; ``cvvdp`` True/False forces it on or off, None scores it on small sequences only:
    :func:`dbench.metrics.video_quality.use_cvvdp`); intervals as in :func:`run_cell` (the
    bootstrap resamples the same pixel blocks in every frame; ``cvvdp``, like the temporal
    figures, gets one only over seeds). ``output`` is the last frame's output of the first seed.
    Where the untimed warm-up ran (a sequence no longer than the warm-up), its outputs of frames
    0-1 are compared with the run's: ``nondeterministic`` where they differ.
    """
    from ..data import BUFFER_NAMES

    seqs = _as_list(seq)
    check_cell_args(method, seqs, metric_names, None, warmup, extra=("t_rmse", "tpsnr", "cvvdp"))
    warmup = WARMUP if warmup is None else int(warmup)
    available = {b for b in BUFFER_NAMES if seqs[0].has(b)}
    ok, reason = applies(method, "sequence", available)
    if not ok:
        return CellResult(method.name, dict(method.params), None, skipped=reason)
    names = [n for n in metric_names if n in judge.JUDGED]
    columns = judge.metric_names(names) + ["t_rmse", "tpsnr", "cvvdp"]
    on_device, where = placement(method, device)
    result = CellResult(method.name, dict(method.params), None, device=where,
                        device_name=device_name(where))
    judgements = []
    for i, s in enumerate(seqs):
        run = run_sequence(method, s, metric_names=names, warmup=warmup, keep_outputs=True,
                           device=where, cvvdp=cvvdp)
        result.transfer_s.append(run.summary.get("transfer_s", 0.0))
        nd = run.nondeterministic  # frames 0-1 of an untimed pass against the run's
        if nd:
            frames = ", ".join(map(str, nd["frames"]))
            note_difference(result, s.meta.get("seed", i), nd,  # (its differences only)
                            f"frame{'s' if len(nd['frames']) > 1 else ''} {frames} in "
                            f"{nd['pass']} and in the run", "the run's calls")
        after = after_warmup(run.per_frame, warmup)
        result.times_s += [r["time_s"] for r in after]
        result.n_nonfinite += int(sum((~np.isfinite(o)).sum() for o in run.outputs))
        if result.sequence is None:
            result.sequence, result.output = run, run.outputs[-1]
            result.settings = resolved_settings(method)
            result.backend = method_backend(method, on_device)
        row = {"seed": s.meta.get("seed", i)}
        row.update({c: run.summary.get(f"mean_{c}", run.summary.get(c, float("nan")))
                    for c in columns + ["ref_rmse"]})
        result.per_seed.append(row)
        judgements.append(run.judgements)
    if any(result.per_seed[0].get(c) == result.per_seed[0].get(c) for c in names):
        result.metrics, result.ci_kind = summarise_seeds(result.per_seed, judgements, columns)
    return result


def cell_record(res, frames: list, needs: set[str]) -> dict[str, Any]:
    """The numbers of one finished cell (shared by ``run`` and ``sweep``); ``needs``: the
    buffers the method used (its ``wants``)."""
    def median_meta(key: str) -> float:
        vals = [f.meta.get(key) for f in frames if f.meta.get(key) is not None]
        return float(statistics.median(vals)) if vals else float("nan")

    first = frames[0]
    record = {"n_seeds": res.n_seeds, "seeds": [f.meta.get("seed") for f in frames],
              "ci_kind": res.ci_kind, "ref_spp": first.meta.get("ref_spp"),
              "ref_seed": first.meta.get("ref_seed"),
              "ref_render_s": first.meta.get("ref_render_s"),
              "render_s": median_meta("render_s"),
              "stats_s": median_meta("stats_s") if "stats" in needs else 0.0,
              # A-SVGF's re-shaded samples are rendered for the methods that use them: their
              # cost per frame counts with the method (docs/temporal.md §2)
              "gradient_s": (median_meta("gradient_per_frame_s") if "gradient" in needs
                             and first.kind == "sequence" else 0.0),
              **res.metrics, "time_s": res.time_s, "time_s_iqr": res.time_s_iqr,
              "times_s": res.times_s, "n_nonfinite": res.n_nonfinite,
              "per_seed": res.per_seed, "machine": machine_label(),
              # what rendered the inputs: a CUDA render is not bit-identical to an LLVM one
              "render_variant": (first.meta.get("versions") or {}).get("variant"),
              "device": res.device, "device_name": res.device_name, "backend": res.backend}
    if res.transfer_s:
        # host↔device copies of a device cell, timed apart from the method (median per seed)
        record["transfer_s"] = float(statistics.median(res.transfer_s))
    if res.settings:
        record["settings"] = res.settings       # what the method resolved (first seed)
    if res.nondeterministic:  # calls on one input differed: the scores are one call's
        record["nondeterministic"] = dict(res.nondeterministic)
    if first.kind == "sequence":
        record.update(frames=len(first), warmup=res.sequence.summary["warmup"])
    return record
