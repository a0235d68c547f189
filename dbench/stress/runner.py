"""Running the stress matrix (:mod:`dbench.stress.cases`): one method on one case
(:func:`run_case`, sequence methods on the first and second frame after ``reset()``), every
method on every case (:func:`run_all`), and ``results/stress.md`` (:func:`stress_markdown`)."""
from __future__ import annotations

import time
import traceback
from dataclasses import dataclass

import numpy as np

from ..data import Frame
from ..errors import DbenchInputError
from ..run import fpenv
from ..run.inputs import first_changed, input_guard, private_copy
from .cases import CASES, TIME_LIMIT_S, Case, _as_sequence_frame


@dataclass
class Outcome:
    status: str  # "pass", "fail" or "n/a"
    why: str
    seconds: float = 0.0


def run_case(method_name: str, case: Case) -> Outcome:
    """Run ``case`` on a fresh ``method_name``. Sequence methods get ``reset()`` and then the
    frame twice: the first call (empty history: spatial estimates, first-frame paths) and the
    second (reprojected history) are judged separately; both must pass."""
    from .. import registry

    method = registry.get(method_name)
    used = set(method.needs) | set(getattr(method, "optional_needs", ()))
    if case.needs_buffer is not None and case.needs_buffer not in used \
            and not case.all_methods:
        return Outcome("n/a", f"{method_name} does not use {case.needs_buffer}")
    if case.kind == "transient":
        if "transient" not in method.kinds:
            return Outcome("n/a", f"{method_name} does not run on transient data")
    elif not (method.kinds & {"steady", "sequence"}):
        return Outcome("n/a", f"{method_name} runs on {sorted(method.kinds)} data only")
    try:
        frame = case.build()
    except DbenchInputError as exc:  # the data type itself refused the input: documented
        return Outcome("pass", f"rejected on construction: {exc}")
    as_sequence = "sequence" in method.kinds and case.kind != "transient"
    if as_sequence:
        try:
            frame = _as_sequence_frame(frame, case)
        except DbenchInputError as exc:
            return Outcome("pass", f"rejected on construction: {exc}")
    # the method's own read-only copy, as in a run (dbench/run/inputs.py): a method that writes
    # to its input fails the case, naming the buffer
    given = private_copy(frame)

    def call(f):
        # f is unchanged when the write raised: the buffer is found against f itself
        with input_guard(method_name, f, lambda spare: fpenv.denoise(method, spare)):
            return fpenv.denoise(method, f)
    outcome = judged_calls(method, case, given, as_sequence, call)
    changed = first_changed(given, frame)
    if changed:
        return Outcome("fail", f"modified its input buffer {changed} (a method must not write "
                       "to its input)", outcome.seconds)
    return outcome


def judged_calls(method, case: Case, frame, as_sequence: bool, call) -> Outcome:
    """``reset()``, then ``call(frame)`` once (twice for a sequence method: the first frame
    after ``reset()``, then the history path), judged by the policy of the module docstring.
    ``call`` is the host ``denoise`` or a device form's (:mod:`dbench.stress.device`).

    Calls over ``TIME_LIMIT_S`` are made once more before they are judged slow: a method's
    first call in a process compiles its kernels (Numba, Triton), which on a loaded machine
    alone can take that long and is no cost of the input."""
    outcome = _judged_once(method, case, frame, as_sequence, call)
    if outcome.seconds > TIME_LIMIT_S:
        outcome = _judged_once(method, case, frame, as_sequence, call)
    return outcome


def _judged_once(method, case: Case, frame, as_sequence: bool, call) -> Outcome:
    needed = case.needs_buffer is not None and case.needs_buffer in method.needs
    t0 = time.perf_counter()
    outs = []
    try:
        method.reset()
        outs.append(call(frame))  # first frame after reset(): no history
        if as_sequence:
            outs.append(call(frame))  # second frame: the history path
    except DbenchInputError as exc:
        seconds = time.perf_counter() - t0
        msg = str(exc)
        names_shape = "expected" in msg or "(H, W" in msg
        may_refuse = case.error_ok and (needed or not case.all_methods)
        if may_refuse and any(b in msg for b in case.error_ok) and names_shape:
            return Outcome("pass", f"DbenchInputError: {msg}", seconds)
        return Outcome("fail", f"unexpected DbenchInputError on frame {len(outs) + 1}: {msg}",
                       seconds)
    except Exception as exc:  # noqa: BLE001
        return Outcome("fail", f"{type(exc).__name__} on frame {len(outs) + 1}: {exc} "
                       f"[{traceback.format_exc(limit=2).splitlines()[-1]}]",
                       time.perf_counter() - t0)
    except SystemExit as exc:  # a method cannot end the stress run: the case fails
        return Outcome("fail", f"called sys.exit({exc.code}) on frame {len(outs) + 1} (a method "
                       "must not end the process)", time.perf_counter() - t0)
    seconds = time.perf_counter() - t0
    if case.error_ok and needed and case.strict:
        return Outcome("fail", f"missing {case.needs_buffer} accepted silently", seconds)
    verdicts = [_judge(frame, np.asarray(o), seconds) for o in outs]
    if len(verdicts) == 1:
        return verdicts[0]
    status = "fail" if any(v.status == "fail" for v in verdicts) else "pass"
    why = "; ".join(f"frame {i + 1}: {v.why}" for i, v in enumerate(verdicts))
    return Outcome(status, why, seconds)


def _judge(frame: Frame, out: np.ndarray, seconds: float) -> Outcome:
    if out.shape != frame.color.shape:
        return Outcome("fail", f"output shape {out.shape}, expected {frame.color.shape}", seconds)
    if out.dtype != np.float32:
        return Outcome("fail", f"output dtype {out.dtype}, expected float32", seconds)
    if seconds > TIME_LIMIT_S:
        return Outcome("fail", f"took {seconds:.1f} s on a tiny image", seconds)
    bad_in = ~np.isfinite(frame.color).all(axis=-1)
    if frame.stats is not None:
        bad_in |= ~np.isfinite(frame.stats.mean).all(axis=-1)
    bad_out = ~np.isfinite(out).all(axis=-1)
    spread = bad_out & ~bad_in
    if spread.any():
        return Outcome("fail", f"non-finite output at {int(spread.sum())} pixel(s) whose input "
                       "is finite", seconds)
    if bad_out.any():
        return Outcome("pass", f"non-finite kept at {int(bad_out.sum())} missing input pixel(s) "
                       "only", seconds)
    return Outcome("pass", "finite output", seconds)


def default_methods() -> list[str]:
    """Every registered method and the ``NAME+gate`` variant of each steady one (``noisy``
    aside: its gate is the identity), sorted."""
    from .. import registry

    names = registry.available()
    gated = [f"{n}+gate" for n in names
             if n != "noisy" and "steady" in registry.method_class(n).kinds]
    return sorted(names + gated)


def run_all(method_names: list[str] | None = None, progress: bool = True
            ) -> dict[str, dict[str, Outcome]]:
    from tqdm.auto import tqdm

    names = method_names or default_methods()
    results: dict[str, dict[str, Outcome]] = {}
    with tqdm(total=len(names) * len(CASES), desc="stress", disable=not progress) as bar:
        for m in names:
            results[m] = {}
            for case in CASES:
                results[m][case.name] = run_case(m, case)
                bar.update()
    return results


def stress_markdown(results: dict[str, dict[str, Outcome]]) -> str:
    import pandas as pd

    from ..report.formats import markdown_table

    symbol = {"pass": "pass", "fail": "**FAIL**", "n/a": "n/a"}
    rows = [{"method": m, **{c.name: symbol[r[c.name].status] for c in CASES}}
            for m, r in results.items()]
    n_fail = sum(o.status == "fail" for r in results.values() for o in r.values())
    n_pass = sum(o.status == "pass" for r in results.values() for o in r.values())
    lines = ["# dbench stress test", "",
             f"{n_pass} passed, {n_fail} failed "
             f"({len(results)} methods × {len(CASES)} cases; n/a where a case does not apply).",
             "", markdown_table(pd.DataFrame(rows)), "", "## Cases", ""]
    lines += ["Sequence methods run `reset()` and then the same frame twice; the first frame "
              "(no history) and the second (reprojected history) must both pass.", ""]
    lines += ["| case | input | expected |", "|---|---|---|"]
    lines += [f"| `{c.name}` | {c.description} | {c.expect} |" for c in CASES]
    lines += ["", "## Policy", "",
              "Pass means: finite float32 output of the input's shape wherever the input is "
              "finite (a non-finite input pixel is missing data; it may stay non-finite in its "
              "own output pixel but must never spread), or a `DbenchInputError` that names the "
              "missing or malformed buffer and the expected shape.", "", "## Details", ""]
    for m, r in results.items():
        for c in CASES:
            o = r[c.name]
            if o.status != "n/a":
                lines.append(f"- {m} / {c.name}: {o.status}: {o.why[:200]}")
    return "\n".join(lines) + "\n"
