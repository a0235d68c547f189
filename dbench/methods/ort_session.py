"""ONNX Runtime sessions for the shipped learned models (``nca``, ``autoencoder``)."""
from __future__ import annotations


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
