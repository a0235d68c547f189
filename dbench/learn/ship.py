"""Shipping trained weights: the ONNX graph and a JSON record of the training (configuration,
data hash, final losses, loss curve, wall time, machine) into the method's package folder."""
from __future__ import annotations

import json

import dataclasses
import os
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ..methods.kernels.hdr_input import noise_level
from .configs import TrainResult
from .loop import loss_curve


PACKAGE_METHODS = Path(__file__).resolve().parent.parent / "methods"


def machine_record() -> dict[str, Any]:
    """The CPU, cores, GPU and torch's thread count of this process (a training record's
    ``machine``)."""
    from ..run.machine import machine_info

    info = machine_info()
    return {"cpu": info["cpu"], "cores": info["cores"], "gpu": info["gpu"],
            "torch_threads": torch.get_num_threads(), "torch": torch.__version__}


def _describe(result: TrainResult, extra: dict) -> dict[str, Any]:
    cfg = dataclasses.asdict(result.config)
    return {"method": result.method, "trained_on": "cpu" if not torch.cuda.is_available()
            else "cuda",
            # a run resumed from shipped weights keeps the machine of stages 1-2; its own stage
            # records where it ran
            "machine": result.previous.get("machine") or machine_record(),
            "training_config": cfg,
            "data": result.data, "losses": result.summary(),
            "loss_curve": loss_curve(result.losses) or result.previous.get("loss_curve", []),
            "created": time.strftime("%Y-%m-%d %H:%M:%S"), **extra}


def _readable(path: Path) -> None:
    """Shipped files are package data: readable by everyone (temporary files are 0600)."""
    os.chmod(path, 0o644)


def steps_table_text(by_spp: dict) -> str:
    """The NCA's per-spp step counts as its metadata stores them: JSON {"spp": steps}."""
    return json.dumps({str(k): int(v) for k, v in by_spp.items()})


def ship_nca(result: TrainResult, out_dir: str | Path | None = None) -> tuple[Path, Path]:
    """Write ``nca.onnx`` (Loop form) and ``nca.json`` into ``out_dir`` (default: the package)."""
    import onnx

    from ..io import atomic_path, write_json
    from ..methods.nca.export import build_onnx
    from ..methods.nca.model import count_parameters

    out = Path(out_dir) if out_dir else PACKAGE_METHODS / "nca"
    out.mkdir(parents=True, exist_ok=True)
    cfg = result.config
    W = result.model.W.detach().numpy().astype(np.float32)
    b = result.model.b.detach().numpy().astype(np.float32)
    meta = {"update_channels": cfg.update_channels, "activation": cfg.activation,
            "color_encoding": cfg.color_encoding, "iterations": str(cfg.iterations),
            "autoexposure": str(bool(cfg.autoexposure)), "data_hash": result.data.get("hash", "")}
    by_spp = result.data.get("iterations_by_spp")
    if by_spp:
        meta["iterations_by_spp"] = steps_table_text(by_spp)
    gate = None
    if getattr(result.model, "noise_gate", False):
        gate = [float(result.model.gate_u.detach()), float(result.model.gate_v.detach()),
                float(result.model.gate_max)]
        meta["noise_gate"] = json.dumps(gate)
    model = build_onnx(W, b, cfg.update_channels, cfg.activation, None, meta)
    with atomic_path(out / "nca.onnx", suffix=".tmp.onnx") as tmp:
        onnx.save(model, str(tmp))
    _readable(out / "nca.onnx")
    info = _describe(result, {
        "parameters": count_parameters(result.model), "iterations": cfg.iterations,
        "iterations_by_spp": by_spp,
        "update_channels": cfg.update_channels, "activation": cfg.activation,
        "color_encoding": cfg.color_encoding, "autoexposure": bool(cfg.autoexposure),
        "noise_gate": gate, "W": W.tolist(), "b": b.tolist()})
    write_json(out / "nca.json", info)
    _readable(out / "nca.json")
    return out / "nca.onnx", out / "nca.json"


def ship_autoencoder(result: TrainResult, out_dir: str | Path | None = None
                     ) -> tuple[Path, Path]:
    """Write ``autoencoder.onnx`` (stateful: hidden states as inputs/outputs) and its JSON."""
    import onnx

    from ..io import atomic_path, write_json
    from ..methods.autoencoder.export import build_onnx
    from ..methods.autoencoder.model import count_parameters

    out = Path(out_dir) if out_dir else PACKAGE_METHODS / "autoencoder"
    out.mkdir(parents=True, exist_ok=True)
    cfg, net = result.config, result.model
    state = {k: v.detach().numpy() for k, v in net.state_dict().items()}
    meta = {"features": ",".join(cfg.features), "width_scale": str(cfg.width_scale),
            "enc_widths": ",".join(map(str, net.enc_widths)),
            "in_channels": str(net.in_channels), "autoexposure": str(bool(cfg.autoexposure)),
            "data_hash": result.data.get("hash", "")}
    model = build_onnx(state, net.in_channels, net.enc_widths, stateful=True, metadata=meta,
                       residual=net.residual, blend=net.blend, level_gate=net.level_channel,
                       gate_max=net.gate_max, pixel_gate=net.pixel_gate)
    gate = None
    if net.level_channel is not None:
        u, v = (float(t) for t in net.level_gate.detach())
        gate = {"u": u, "v": v, "gate_max": net.gate_max, "channel": net.level_channel,
                "gamma_at_spp": {str(n): net.gate_max / (1.0 + np.exp(-(v + u * noise_level(n))))
                                 for n in (1, 4, 16, 64, 256, 1024)}}
    with atomic_path(out / "autoencoder.onnx", suffix=".tmp.onnx") as tmp:
        onnx.save(model, str(tmp))
    _readable(out / "autoencoder.onnx")
    info = _describe(result, {
        "parameters": count_parameters(net), "in_channels": net.in_channels,
        "features": list(cfg.features), "width_scale": cfg.width_scale,
        "enc_widths": list(net.enc_widths), "dec_widths": list(net.dec_widths),
        "recurrent": cfg.recurrent, "residual": net.residual, "blend": net.blend,
        "level_gate": gate, "pixel_gate": net.pixel_gate,
        "autoexposure": bool(cfg.autoexposure)})
    write_json(out / "autoencoder.json", info)
    _readable(out / "autoencoder.json")
    return out / "autoencoder.onnx", out / "autoencoder.json"
