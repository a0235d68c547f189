"""ONNX Runtime sessions for the shipped learned models (``nca``, ``autoencoder``)."""
from __future__ import annotations

from pathlib import Path
from typing import Any

from ..errors import DbenchInputError
from .fpenv import kept_fp_environment


def check_weights(weights: Any, method: str) -> None:
    """Refuse, when the method is built (before anything renders), a ``weights`` parameter that
    is not a readable ONNX file: one line naming it instead of a traceback later."""
    if weights is None:
        return
    p = Path(str(weights))
    if not p.is_file():
        what = "a folder" if p.is_dir() else "missing"
        raise DbenchInputError(f"{method}.weights: {p} is {what}; expected the path of a "
                               f"{method}.onnx file (or leave it unset for the shipped model)")
    import onnx

    try:
        onnx.load(str(p), load_external_data=False)
    except Exception as exc:  # noqa: BLE001 - any parse failure means "not an ONNX model"
        raise DbenchInputError(f"{method}.weights: {p} is not an ONNX model "
                               f"({type(exc).__name__}); expected a {method}.onnx file") from None


class KeptEnvironmentSession:
    """An ``onnxruntime.InferenceSession`` whose ``run`` leaves the calling thread's
    floating-point environment as it found it (:mod:`dbench.methods.fpenv`); every other
    attribute is the session's."""

    def __init__(self, session: Any) -> None:
        self.session = session

    def run(self, *args: Any, **kwargs: Any) -> Any:
        with kept_fp_environment():
            return self.session.run(*args, **kwargs)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.session, name)


def cpu_session(model_bytes: bytes, threads: int | None = None) -> KeptEnvironmentSession:
    """An ``onnxruntime.InferenceSession`` on the CPU provider for a serialised ONNX model.

    Denormals are flushed to zero inside the session (tiny activations otherwise slow the
    convolutions by orders of magnitude), and worker threads do not spin between operators: on
    a shared machine spinning threads starve the other processes. ONNX Runtime sets
    flush-to-zero on the calling thread too, when the process's first session is built, and
    leaves it so; the session is built and run inside
    :func:`~dbench.methods.fpenv.kept_fp_environment`, so the caller's arithmetic keeps its
    subnormal values. ``threads``: intra-op threads (None: ONNX Runtime's default, one per
    core).
    """
    import onnxruntime as ort

    so = ort.SessionOptions()
    so.log_severity_level = 3
    so.add_session_config_entry("session.set_denormal_as_zero", "1")
    so.add_session_config_entry("session.intra_op.allow_spinning", "0")
    if threads:
        so.intra_op_num_threads = int(threads)
    with kept_fp_environment():
        session = ort.InferenceSession(model_bytes, so, providers=["CPUExecutionProvider"])
    return KeptEnvironmentSession(session)
