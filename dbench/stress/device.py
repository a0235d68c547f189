"""The stress cases against each method's device path (docs/gpu.md §2), in its CPU-testable
form: the frame uploaded as CPU tensors, ``denoise_device`` called (Triton kernels through the
interpreter, PyTorch ops, OIDN's CPU device), the output downloaded and judged by the same rules
as the host path (:mod:`dbench.stress.cases`): finite output wherever the input is finite, or a
DbenchInputError naming the buffer.

``jbf`` and ``statistical`` run with radius 2 here: the interpreter's time grows with the
window (about 27 s a call at radius 20 on a 16 × 24 frame), and the kernel's code is the same
for every radius (a compile-time loop bound). The transient cases run on the device form of
``statistical``, the one method with a device path for videos.
"""
from __future__ import annotations

from ..device import download, upload
from ..errors import DbenchInputError
from ..run import fpenv
from .cases import Case, _as_sequence_frame
from .runner import Outcome, judged_calls

#: Parameters of the device forms that differ from the defaults, with the reason above.
DEVICE_FORM_PARAMS: dict[str, dict] = {"jbf": {"radius": 2}, "statistical": {"radius": 2}}
#: The suffix of a device form's row in the stress matrix.
SUFFIX = " [device form]"


def device_methods() -> list[str]:
    """Registered methods with a device path, sorted."""
    from .. import registry
    return sorted(n for n in registry.available() if registry.method_class(n).has_device_path())


def run_device_case(method_name: str, case: Case) -> Outcome:
    """:func:`dbench.stress.runner.run_case` for the device path of ``method_name`` on CPU
    tensors (sequence methods: two calls after ``reset()``, both judged)."""
    from .. import registry

    method = registry.get(method_name, **DEVICE_FORM_PARAMS.get(method_name, {}))
    used = set(method.needs) | set(getattr(method, "optional_needs", ()))
    if case.needs_buffer is not None and case.needs_buffer not in used and not case.all_methods:
        return Outcome("n/a", f"{method_name} does not use {case.needs_buffer}")
    # a method that runs on transient data takes it on its device path too (``statistical``)
    if (case.kind == "transient" and "transient" not in method.kinds) \
            or not method.runs_on_device():
        return Outcome("n/a", f"{method_name} has no device path for this input")
    try:
        frame = case.build()
        as_sequence = "sequence" in method.kinds and case.kind != "transient"
        if as_sequence:
            frame = _as_sequence_frame(frame, case)
    except DbenchInputError as exc:
        return Outcome("pass", f"rejected on construction: {exc}")
    # the upload copies (never views) the frame, as the harness's does
    return judged_calls(method, case, frame, as_sequence,
                        lambda f: download(fpenv.denoise_device(method, upload(f, "cpu"))))


def run_device_forms(method_names: list[str] | None = None, progress: bool = True
                     ) -> dict[str, dict[str, Outcome]]:
    """Every case against the device form of each of ``method_names`` (default: every method
    with a device path), as rows ``NAME [device form]`` of the stress matrix."""
    from tqdm.auto import tqdm

    from .cases import CASES

    forms = [m for m in device_methods() if method_names is None or m in method_names]
    results: dict[str, dict[str, Outcome]] = {}
    with tqdm(total=len(forms) * len(CASES), desc="stress (device forms)",
              disable=not progress) as bar:
        for m in forms:
            results[m + SUFFIX] = {}
            for case in CASES:
                results[m + SUFFIX][case.name] = run_device_case(m, case)
                bar.update()
    return results


__all__ = ["DEVICE_FORM_PARAMS", "SUFFIX", "device_methods", "run_device_case",
           "run_device_forms"]
