"""A finished sweep cell as `dbench sweep` writes it (dbench/run/harness.py, cell_record), made
up for report tests that need no rendering: every headline metric ``err`` with a 1 % interval."""
from __future__ import annotations


def ok_cell(scene: str, spp: int, method: str, err: float = 0.03,
            base_method: str | None = None) -> dict:
    c = {"status": "ok", "scene": scene, "method": method,
         "base_method": base_method or method, "spp": spp,
         "res": 16, "n_seeds": 1, "seeds": [0], "ci_kind": "block bootstrap", "ref_spp": 64,
         "ref_rmse": 1e-4, "time_s": 0.01, "time_s_iqr": 0.0, "render_s": 0.01,
         "n_nonfinite": 0, "params": {}}
    for k in ("rmse", "rmse_surface", "relmse", "relmse_surface", "ssim", "flip"):
        c[k], c[k + "_ci"] = err, err * 0.01
    return c
