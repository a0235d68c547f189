"""The harness's side of the method contract under stress: methods that break it, each with
the documented behaviour of the harness (README "Add your own denoiser"; dbench/run/inputs.py).

| case | the method | expected |
|---|---|---|
| ``mutates_input`` | ``data.color *= 0`` | MethodError naming it: "modified its input" |
| ``mutates_via_torch`` | writes through ``torch.from_numpy`` | MethodError naming the buffer |
| ``raises`` | raises RuntimeError | the error reaches the caller unchanged (``run`` names it in "Failed", a sweep writes an error cell) |
| ``wrong_shape`` | returns (H−1, W, 3) | DbenchInputError naming the output and the expected shape |
| ``exits`` | calls ``sys.exit(3)`` | SystemExit reaches the caller, which records it as the method's failure |

In every case the frame the caller holds is unchanged afterwards. The methods are not
registered (the registry stays as it is).
"""
from __future__ import annotations

import warnings
from typing import Any, Callable

import numpy as np

from ..denoiser import Denoiser
from ..errors import DbenchInputError
from ..run.inputs import MethodError, first_changed, private_copy
from .runner import Outcome
from ..synthetic import base_frame


def _method(name: str, fn: Callable[[Any], Any]) -> Denoiser:
    cls = type(name, (Denoiser,), {"kinds": {"steady"}, "needs": {"color"}, "name": name,
                                   "denoise": lambda self, data: fn(data)})
    return cls()


def _mutate(data):
    data.color *= 0
    return data.color


def _mutate_torch(data):
    import torch
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "the given NumPy array is not writable"
        torch.from_numpy(data.color).mul_(0)
    return np.zeros_like(data.color)


def _raise(data):
    raise RuntimeError("broken method")


def _exit(data):
    raise SystemExit(3)


#: (case, method body, exception type expected, text the message must hold)
CONTRACT_CASES = (
    ("mutates_input", _mutate, MethodError, "modified its input"),
    ("mutates_via_torch", _mutate_torch, MethodError, "modified its input buffer color"),
    ("raises", _raise, RuntimeError, "broken method"),
    ("wrong_shape", lambda d: np.asarray(d.color)[1:].copy(), DbenchInputError,
     "expected shape"),
    ("exits", _exit, SystemExit, "3"),
)


def run_contract_case(case: str) -> Outcome:
    """Run one case through :func:`dbench.run.harness.run_cell`; pass when the expected
    exception arrives with its text and the caller's frame is unchanged."""
    from ..run.harness import run_cell

    _, fn, expected, text = next(c for c in CONTRACT_CASES if c[0] == case)
    frame = base_frame(8, 8)
    kept = private_copy(frame)
    try:
        run_cell(_method(f"stress-{case}", fn), frame, repeats=1)
        outcome = Outcome("fail", f"no error; expected {expected.__name__}")
    except BaseException as exc:  # noqa: BLE001 - SystemExit is one of the cases
        if isinstance(exc, KeyboardInterrupt):
            raise
        message = str(exc.code) if isinstance(exc, SystemExit) else str(exc)
        ok = isinstance(exc, expected) and text in message
        outcome = Outcome("pass" if ok else "fail", f"{type(exc).__name__}: {message[:160]}")
    changed = first_changed(frame, kept)
    if changed:
        outcome = Outcome("fail", f"the caller's frame changed: {changed}")
    return outcome


def contract_markdown() -> str:
    """The cases and their outcomes as a Markdown section of results/stress.md."""
    lines = ["## The harness against methods that break the contract", "",
             "| case | outcome | what happened |", "|---|---|---|"]
    for case, *_ in CONTRACT_CASES:
        o = run_contract_case(case)
        lines.append(f"| `{case}` | {o.status} | {o.why} |")
    return "\n".join(lines) + "\n"


__all__ = ["CONTRACT_CASES", "contract_markdown", "run_contract_case"]
