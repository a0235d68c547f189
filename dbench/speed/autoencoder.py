"""``dbench bench autoencoder`` extra figures: ONNX Runtime (the stateless single-frame graph)
against the PyTorch reference model, same frame."""
from __future__ import annotations



def benchmark(height: int = 720, width: int = 1280, repeats: int = 3) -> dict:
    from .timing import median_time
    from ..synthetic import base_frame
    from ..methods.autoencoder import autoencoder_denoise, model_info, reference_denoise

    f = base_frame(height, width)


    args = (f.color, f.albedo, f.normal, f.depth)
    fast = median_time(lambda: autoencoder_denoise(*args), repeats)
    ref = median_time(lambda: reference_denoise(*args), repeats)
    return {"enc_widths": list(model_info()["enc_widths"]), "onnxruntime_s": fast,
            "pytorch_reference_s": ref, "speedup": ref / fast}
