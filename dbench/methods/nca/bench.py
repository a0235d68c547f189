"""``dbench bench nca`` extra figures: the ONNX Runtime fast path against the PyTorch reference
(perception with kornia filters + the 39x9 product), same frame, same step count."""
from __future__ import annotations

import statistics
import time


def benchmark(height: int = 720, width: int = 1280, repeats: int = 3) -> dict:
    from ...bench.stress import base_frame
    from . import default_iterations, nca_denoise, reference_denoise

    f = base_frame(height, width)
    k = default_iterations()

    def timed(fn):
        fn()
        ts = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            fn()
            ts.append(time.perf_counter() - t0)
        return statistics.median(ts)

    fast = timed(lambda: nca_denoise(f.color, f.normal, f.albedo))
    ref = timed(lambda: reference_denoise(f.color, f.normal, f.albedo))
    return {"iterations": k, "onnxruntime_s": fast, "pytorch_reference_s": ref,
            "speedup": ref / fast}
