"""Choose the shipped NCA's inference step counts again, on its held-out training scenes, without
retraining: the selection :func:`~dbench.learn.train_nca.select_iterations` that ``dbench train
nca`` runs after training, with the settings of :class:`~dbench.learn.configs.NCAConfig`.

    python -m dbench.learn.select_steps [--weights PATH] [--dry-run]

The training set is rebuilt through the render cache with the settings recorded in ``nca.json``
(its hash is recorded with the selection: another CPU rounds some samples differently, so it may
differ from the weights' data hash); the last 4 scenes are the held-out ones, as in training.
The model file keeps its weights; its metadata ``iterations`` (the 1-spp count, used when a
frame's spp is unknown) and ``iterations_by_spp`` are rewritten, and ``nca.json`` records the
new selection table.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path
from typing import Any, Sequence


def held_out_set(info: dict[str, Any], n_validation: int = 4):
    """(training part, held-out part) of the training set ``info`` (an ``nca.json``) records,
    rebuilt through the cache (a differing hash is reported, see the module docstring)."""
    from .. import datasets
    from .dataset import build_training_set
    from .train import TRAINING_SPP, split

    data = info["data"]
    ts = build_training_set(n_scenes=int(data["n_scenes"]), res=int(data["res"]),
                            spp=tuple(data.get("spp", TRAINING_SPP)),
                            ref_spp=int(data["ref_spp"]),
                            family_seed=int(data.get("family_seed", 0)),
                            cache=datasets.Cache(), progress=False)
    train, held = split(ts, n_validation)
    if train.hash != data["hash"]:
        # the same scenes, seeds and settings; another CPU rounds some samples differently
        # (about 1e-7 relative), so the hash is recorded beside the selection, not enforced
        print(f"note: rebuilt training set hashes to {train.hash[:16]}…, the weights' record "
              f"says {data['hash'][:16]}… (same settings, renders from another machine)")
    return train, held


def torch_model(info: dict[str, Any]):
    """The PyTorch NCA with the weights and step-size gate of an ``nca.json``."""
    import numpy as np
    import torch

    from ..methods.nca.model import NCA

    gate = info.get("noise_gate")
    nca = NCA(info["update_channels"], info["activation"], noise_gate=gate is not None,
              gate_init=tuple(gate[:2]) if gate else (0.0, 0.0),
              gate_max=float(gate[2]) if gate else 1.0)
    with torch.no_grad():
        nca.W.copy_(torch.from_numpy(np.asarray(info["W"], np.float32)))
        nca.b.copy_(torch.from_numpy(np.asarray(info["b"], np.float32)))
    return nca


def main(argv: Sequence[str] | None = None) -> int:
    import onnx

    from ..io import atomic_path, write_json
    from ..methods.nca import SHIPPED_JSON, SHIPPED_ONNX
    from .configs import NCAConfig
    from .ship import steps_table_text
    from .train_nca import select_iterations

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--weights", default=str(SHIPPED_ONNX), help="nca.onnx (nca.json beside it)")
    p.add_argument("--dry-run", action="store_true", help="print the selection, write nothing")
    args = p.parse_args(argv)
    onnx_path = Path(args.weights)
    json_path = onnx_path.with_suffix(".json") if onnx_path != SHIPPED_ONNX else SHIPPED_JSON
    info = json.loads(json_path.read_text(encoding="utf-8"))
    cfg = dataclasses.replace(NCAConfig(), **{k: v for k, v in info["training_config"].items()
                                              if k in NCAConfig.__dataclass_fields__
                                              and not k.startswith("select_")})
    train, held = held_out_set(info)
    chosen, table = select_iterations(torch_model(info), held, cfg.select_from,
                                      cfg.color_encoding, cfg.select_by, cfg.autoexposure,
                                      cfg.select_metric, cfg.select_per_spp,
                                      cfg.select_tolerance)
    by_spp = chosen if isinstance(chosen, dict) else None
    default = chosen[min(chosen)] if by_spp else chosen
    print(json.dumps({"iterations": default, "iterations_by_spp": by_spp,
                      "selection": table}, indent=1))
    if args.dry_run:
        return 0
    model = onnx.load(str(onnx_path))
    meta = {e.key: e.value for e in model.metadata_props}
    meta["iterations"] = str(default)
    meta.pop("iterations_by_spp", None)
    if by_spp:
        meta["iterations_by_spp"] = steps_table_text(by_spp)
    del model.metadata_props[:]
    for key, value in meta.items():
        entry = model.metadata_props.add()
        entry.key, entry.value = key, value
    with atomic_path(onnx_path, suffix=".tmp.onnx") as tmp:
        onnx.save(model, str(tmp))
    info["iterations"] = default
    info["iterations_by_spp"] = by_spp
    info["training_config"].update(select_metric=cfg.select_metric,
                                   select_per_spp=cfg.select_per_spp,
                                   select_tolerance=cfg.select_tolerance, iterations=default)
    info["data"]["iterations_selection"] = table
    info["data"]["iterations_by_spp"] = by_spp
    info["data"]["selection_data_hash"] = train.hash
    info["selected"] = time.strftime("%Y-%m-%d %H:%M:%S")
    write_json(json_path, info)
    for path in (onnx_path, json_path):  # package data: readable by everyone
        path.chmod(0o644)
    print(f"wrote {onnx_path} and {json_path}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
