"""ONNX Runtime sessions for the shipped learned models (``nca``, ``autoencoder``)."""
from __future__ import annotations

from pathlib import Path
from typing import Any

from ..errors import DbenchInputError


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


def cpu_session(model_bytes: bytes, threads: int | None = None):
    """An ``onnxruntime.InferenceSession`` on the CPU provider for a serialised ONNX model.

    Denormals are flushed to zero (tiny activations otherwise slow the convolutions by orders of
    magnitude) and worker threads do not spin between operators: on a shared machine spinning
    threads starve the other processes. ``threads``: intra-op threads (None: ONNX Runtime's
    default, one per core).
    """
    import onnxruntime as ort

    so = ort.SessionOptions()
    so.log_severity_level = 3
    so.add_session_config_entry("session.set_denormal_as_zero", "1")
    so.add_session_config_entry("session.intra_op.allow_spinning", "0")
    if threads:
        so.intra_op_num_threads = int(threads)
    return ort.InferenceSession(model_bytes, so, providers=["CPUExecutionProvider"])
