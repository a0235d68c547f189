"""``dbench bench autoencoder`` extra figures: ONNX Runtime (the stateless single-frame graph)
against the PyTorch reference model, same frame."""
from __future__ import annotations

import statistics
import time


def benchmark(height: int = 720, width: int = 1280, repeats: int = 3) -> dict:
    from ...bench.stress import base_frame
    from . import autoencoder_denoise, model_info, reference_denoise

    f = base_frame(height, width)

    def timed(fn):
        fn()
        ts = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            fn()
            ts.append(time.perf_counter() - t0)
        return statistics.median(ts)

    args = (f.color, f.albedo, f.normal, f.depth)
    fast = timed(lambda: autoencoder_denoise(*args))
    ref = timed(lambda: reference_denoise(*args))
    return {"enc_widths": list(model_info()["enc_widths"]), "onnxruntime_s": fast,
            "pytorch_reference_s": ref, "speedup": ref / fast}
