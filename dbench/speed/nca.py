"""``dbench bench nca`` extra figures: the ONNX Runtime fast path against the PyTorch reference
(perception with kornia filters + the 39x9 product), same frame, same step count (the model's
count for the frame's spp)."""
from __future__ import annotations


def benchmark(height: int = 720, width: int = 1280, repeats: int = 3, spp: int = 16) -> dict:
    from .timing import median_time
    from ..synthetic import base_frame
    from ..methods.nca import default_iterations, nca_denoise, reference_denoise

    f = base_frame(height, width, spp=spp)
    k = default_iterations(spp=spp)
    fast = median_time(lambda: nca_denoise(f.color, f.normal, f.albedo, k, spp=spp), repeats)
    ref = median_time(lambda: reference_denoise(f.color, f.normal, f.albedo, k, spp=spp),
                      repeats)
    return {"iterations": k, "onnxruntime_s": fast, "pytorch_reference_s": ref,
            "speedup": ref / fast}
