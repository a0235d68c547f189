"""``nca``: TNND, the tiny neural cellular automaton denoiser (docs/methods/nca.md), served with ONNX
Runtime from the shipped ``nca.onnx`` (trained by ``dbench train nca``; ``nca.json`` beside it
holds the training configuration, data hash, losses, W and b).

Pipeline (shapes for an H x W frame):

    color, normal, albedo (H, W, 3) --encode--> state (1, 9, H, W)
      --ONNX Runtime, `iterations` steps of Pad(edge) -> Conv 9->9 3x3 -> sigmoid -> + b -> + s-->
    RGB state (1, 3, H, W) --decode: max(expm1(.), 0) [· a_eff]--> (H, W, 3)

The colour encoding is stored in the model (``codec.py``): ``log1p`` or ``log1p_demodulated``
(colour divided by the effective albedo before ``log1p``, multiplied back after ``expm1``).

The automaton is size-agnostic: any H, W >= 1 works without padding.

Input policy (documented finite result): non-finite or negative colour values are treated as
missing and replaced by 0 before encoding; non-finite normal/albedo values by 0; normals are
clipped to [-1, 1] and albedo to [0, 1]. A NaN is therefore never spread: the output is finite
everywhere. Missing or mis-shaped buffers raise DbenchInputError naming the buffer.

Optional ``emitter`` buffer (coverage of lights seen directly or in smooth mirrors): those
pixels keep the input in proportion to their coverage (:func:`keep_emitters`).

Device path (``denoise_device``, :mod:`.device`): the same pipeline in PyTorch on the frame's
device, equal to this one within the tolerance tests/methods/test_nca_device.py states.

Parameters: ``iterations`` (None: the model's step count for the frame's spp, from the table
chosen on held-out training scenes and stored in the model, :func:`default_iterations`),
``weights`` (path of another ``nca.onnx``; None: the shipped file), ``threads`` (ONNX Runtime
intra-op threads; None: its default, all physical cores), ``spp`` (the input's sample count for
the noise gate and the step count; None: ``data.meta["spp"]``, which every dbench loader
records, and 1 spp when that is absent too).

HDR input ([dbench], stored in the model's metadata): with ``autoexposure`` the colour is scaled
by OIDN's auto-exposure (:func:`dbench.methods.hdr_input.autoexposure`) before ``log1p`` and the
output divided by it; with ``noise_gate`` = (u, v, γ_max) every automaton step is scaled by
γ = γ_max sigmoid(v + u · log2(spp)/10) (:mod:`.model`).

Example:
    >>> import numpy as np
    >>> from dbench.data import Frame
    >>> from dbench.registry import get
    >>> f = Frame(color=np.full((5, 7, 3), 0.5), albedo=np.full((5, 7, 3), 0.5),
    ...           normal=np.dstack([np.zeros((5, 7, 2)), np.ones((5, 7))]))
    >>> get("nca").denoise(f).shape
    (5, 7, 3)
"""
from __future__ import annotations

import json
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from ...data import check_buffer
from ...errors import DbenchInputError
from ...denoiser import Denoiser, register
from ..kernels.emitters import keep_emitters
from ..kernels.hdr_input import autoexposure, check_run_options, frame_spp, noise_level
from ..kernels.learned_input import decode_planar, encode_planar
from ..ort_session import cpu_session
from .codec import decode, encode

SHIPPED_ONNX = Path(__file__).resolve().parent / "nca.onnx"
SHIPPED_JSON = Path(__file__).resolve().parent / "nca.json"


@lru_cache(maxsize=8)
def _model_info(path: str) -> dict[str, Any]:
    import onnx

    from .export import metadata, weights_from_onnx

    p = Path(path)
    if not p.exists():
        raise DbenchInputError(f"weights: {p} does not exist; run `dbench train nca` or pass "
                               "the path of an nca.onnx")
    model = onnx.load(str(p))
    W, b = weights_from_onnx(model)
    meta = metadata(model)
    gate = json.loads(meta["noise_gate"]) if "noise_gate" in meta else None
    return {"W": W, "b": b, "update_channels": meta.get("update_channels", "all"),
            "activation": meta.get("activation", "sigmoid"),
            "encoding": meta.get("color_encoding", "log1p"),
            "iterations": int(meta.get("iterations", 16)),
            "iterations_by_spp": {int(k): int(v) for k, v in
                                  json.loads(meta.get("iterations_by_spp", "{}")).items()},
            "noise_gate": None if gate is None else (float(gate[0]), float(gate[1])),
            "gate_max": 1.0 if gate is None or len(gate) < 3 else float(gate[2]),
            "autoexposure": meta.get("autoexposure") == "True"}


def step_size(path: str, spp: float | None) -> float:
    """γ(ℓ) = sigmoid(v + u ℓ) of the model at ``path`` for a frame of ``spp`` samples
    (float32 arithmetic, as in PyTorch); 1.0 for a model without the noise gate; unknown spp
    counts as 1 spp (ℓ = 0: the strongest smoothing the model learnt)."""
    gate = _model_info(path)["noise_gate"]
    if gate is None:
        return 1.0
    level = np.float32(0.0 if spp is None else noise_level(spp))
    z = np.float32(gate[1]) + np.float32(gate[0]) * level
    sig = np.float32(1.0) / (np.float32(1.0) + np.exp(-z, dtype=np.float32))
    return float(np.float32(_model_info(path)["gate_max"]) * sig)


@lru_cache(maxsize=32)
def _session(path: str, iterations: int, threads: int | None, gamma: float = 1.0):
    """An ONNX Runtime session of the unrolled automaton (built in memory from the weights)
    with step size ``gamma``."""
    from .export import build_onnx

    info = _model_info(path)
    model = build_onnx(info["W"], info["b"], info["update_channels"], info["activation"],
                       iterations=iterations, gamma=gamma)
    return cpu_session(model.SerializeToString(), threads)


def default_iterations(weights: str | Path | None = None, spp: float | None = None) -> int:
    """The model's step count for a frame of ``spp`` samples: from its per-sample-count table
    (metadata ``iterations_by_spp``, chosen on held-out training scenes) the entry nearest in
    log2(spp), unknown spp counting as 1 spp; without a table its single trained default."""
    info = _model_info(str(weights or SHIPPED_ONNX))
    table = info["iterations_by_spp"]
    if not table:
        return info["iterations"]
    level = 0.0 if spp is None else float(np.log2(max(float(spp), 1.0)))
    nearest = min(table, key=lambda n: (abs(np.log2(n) - level), n))
    return table[nearest]


def nca_denoise(color: np.ndarray, normal: np.ndarray, albedo: np.ndarray,
                iterations: int | None = None, weights: str | Path | None = None,
                threads: int | None = None, spp: float | None = None) -> np.ndarray:
    """Denoise (H, W, 3) linear colour with (H, W, 3) normal and albedo; returns (H, W, 3)
    float32 (docs/methods/nca.md; input policy in the module docstring). ``spp``: the colour's sample
    count, for the noise gate (None counts as 1 spp)."""
    color = check_buffer("color", color, (None, None, 3))
    h, w = color.shape[:2]
    normal = check_buffer("normal", normal, (h, w, 3))
    albedo = check_buffer("albedo", albedo, (h, w, 3))
    path = str(weights or SHIPPED_ONNX)
    k = default_iterations(path, spp) if iterations is None else iterations
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 0:
        raise DbenchInputError(f"iterations: expected an integer >= 0, got {k!r}")
    info = _model_info(path)
    enc = info["encoding"]
    exposure = autoexposure(color) if info["autoexposure"] else 1.0
    # codec.encode and codec.decode in compiled passes (kernels/learned_input.py, tested equal
    # within 1e-6)
    state = encode_planar(color, {"albedo": albedo, "normal": normal}, ("normal", "albedo"),
                          exposure, demodulate=enc == "log1p_demodulated")[0][None]
    gamma = step_size(path, spp)
    rgb = _session(path, int(k), threads, gamma).run(None, {"state": state})[0][0]
    return decode_planar(rgb, albedo, enc == "log1p_demodulated", exposure)


def reference_denoise(color: np.ndarray, normal: np.ndarray, albedo: np.ndarray,
                      iterations: int | None = None, weights: str | Path | None = None,
                      spp: float | None = None) -> np.ndarray:
    """The same result through the readable PyTorch model (perception + 39x9 product)."""
    import torch

    from .model import NCA

    info = _model_info(str(weights or SHIPPED_ONNX))
    k = default_iterations(weights, spp) if iterations is None else iterations
    gate = info["noise_gate"]
    nca = NCA(info["update_channels"], info["activation"], noise_gate=gate is not None,
              gate_init=gate or (0.0, 0.0), gate_max=info["gate_max"])
    with torch.no_grad():
        nca.W.copy_(torch.from_numpy(info["W"]))
        nca.b.copy_(torch.from_numpy(info["b"]))
        color = check_buffer("color", color, (None, None, 3))
        h, w = color.shape[:2]
        albedo = check_buffer("albedo", albedo, (h, w, 3))
        exposure = autoexposure(color) if info["autoexposure"] else 1.0
        s = torch.from_numpy(encode(color, check_buffer("normal", normal, (h, w, 3)), albedo,
                                    info["encoding"], exposure))[None]
        level = 0.0 if spp is None else noise_level(spp)
        rgb = nca(s, int(k), level)[0, :3].numpy()
    return decode(rgb, albedo, info["encoding"], exposure)


def training_info(path: str | Path = SHIPPED_JSON) -> dict[str, Any]:
    """The JSON written beside the shipped weights (training configuration, losses, ...)."""
    return json.loads(Path(path).read_text(encoding="utf-8"))


@register("nca")
class NCADenoiser(Denoiser):
    """TNND (docs/methods/nca.md): 360 trained numbers (362 with the noise gate), ``iterations``
    automaton steps."""

    kinds = {"steady"}
    needs = {"color", "normal", "albedo"}
    optional_needs = {"emitter"}
    keeps_emitters = True  # denoise ends with keep_emitters; NAME+gate does not repeat it
    defaults = dict(iterations=None, weights=None, threads=None, spp=None)

    device_backend = "torch"

    def __init__(self, **params):
        super().__init__(**params)
        from ..ort_session import check_weights
        check_weights(self.params["weights"], "nca")
        # refused here, before anything renders, not on the first frame
        v = self.params["iterations"]
        if v is not None and (isinstance(v, bool) or not isinstance(v, int) or v < 0):
            raise DbenchInputError(f"iterations: expected an integer >= 0, got {v!r}")
        check_run_options(self.params)
        self._device_nets: dict[str, Any] = {}  # the PyTorch automaton per device

    def denoise(self, data) -> np.ndarray:
        for name in ("normal", "albedo"):
            if getattr(data, name, None) is None:
                raise DbenchInputError(f"{name}: missing; nca needs an (H, W, 3) {name} buffer")
        out = nca_denoise(data.color, data.normal, data.albedo, self.params["iterations"],
                          self.params["weights"], self.params["threads"],
                          frame_spp(data, self.params["spp"]))
        return keep_emitters(data.color, out, getattr(data, "emitter", None))

    def denoise_device(self, data):
        """The same pipeline in PyTorch on the frame's device (:mod:`.device`): (H, W, 3)
        float32 tensor; every parameter as ``denoise``, ``threads`` setting PyTorch's CPU
        threads on a CPU device and refused on a GPU."""
        from .device import denoise_device

        path = str(self.params["weights"] or SHIPPED_ONNX)
        spp = frame_spp(data, self.params["spp"])
        k = default_iterations(path, spp) if self.params["iterations"] is None \
            else self.params["iterations"]
        return denoise_device(self, data, _model_info(path), spp, k)


__all__ = ["NCADenoiser", "keep_emitters", "nca_denoise", "reference_denoise",
           "default_iterations", "training_info", "SHIPPED_ONNX", "SHIPPED_JSON"]
