"""Training the ``nca`` denoiser (docs/methods/nca.md §4-5): random iteration count per batch (loss only
after the last step), MSE + 0.5 L_g on log1p RGB plus [dbench] 1.0 x the relative linear MSE,
Adam, per-parameter gradient normalisation; the inference step count chosen on held-out scenes,
worst case first (:func:`select_iterations`)."""
from __future__ import annotations

import dataclasses

import numpy as np
import torch

from . import losses as L
from .configs import NCAConfig, TrainResult
from .dataset import TrainingSet, full_images, sample_batch
from .loop import (add_linear_terms, lr_at, make_optimizer, run_loop, seed_everything, set_lr,
                   to_tensor)


def _a_eff(albedo: torch.Tensor) -> torch.Tensor:
    return torch.where(albedo > 1e-3, albedo, torch.ones_like(albedo))


def nca_state(batch: dict[str, np.ndarray], encoding: str = "log1p") -> torch.Tensor:
    """(B, 9, h, w) initial state from a batch: encoded colour, normal, albedo (docs/methods/nca.md §1;
    encodings as in ``methods/nca/codec.py``)."""
    color = to_tensor(batch["noisy"])
    if encoding == "log1p_demodulated":
        color = color / _a_eff(to_tensor(batch["albedo"]))
    return torch.cat([torch.log1p(color), to_tensor(batch["normal"]), to_tensor(batch["albedo"])], dim=1)


def nca_prediction(out_rgb: torch.Tensor, batch: dict[str, np.ndarray], encoding: str
                   ) -> torch.Tensor:
    """log1p of the (remodulated) output, compared with log1p(reference)."""
    if encoding == "log1p_demodulated":
        return torch.log1p(torch.expm1(out_rgb.clamp(max=20.0)) * _a_eff(to_tensor(batch["albedo"])))
    return out_rgb


def train_nca(ts: TrainingSet, cfg: NCAConfig | None = None, progress: bool = False,
              validation: TrainingSet | None = None) -> TrainResult:
    """Train the 360-parameter automaton on crops of ``ts``."""
    from ..methods.nca.model import NCA

    cfg = cfg or NCAConfig()
    rng = seed_everything(cfg.seed, cfg.threads)
    gen = torch.Generator().manual_seed(cfg.seed)
    model = NCA(cfg.update_channels, cfg.activation, cfg.bias_init, cfg.w_init_std,
                generator=gen, noise_gate=cfg.noise_gate, gate_init=cfg.gate_init,
                gate_max=cfg.gate_max)
    opt = make_optimizer(model, cfg.lr, lambda n: n.startswith("gate_"), cfg.gate_lr)

    def step_fn(step: int):
        set_lr(opt, lr_at(step, cfg))
        batch = sample_batch(ts, rng, cfg.batch, cfg.crop, cfg.spp_choices,
                             cfg.light_fraction, cfg.mix_spp, cfg.autoexposure)
        k = int(rng.integers(cfg.k_min, cfg.k_max + 1))
        out = model(nca_state(batch, cfg.color_encoding), k,
                    torch.from_numpy(batch["level"]))[:, :3]
        pred = nca_prediction(out, batch, cfg.color_encoding)
        target = torch.log1p(to_tensor(batch["reference"]))
        loss, part = L.nca_loss(pred, target, cfg.loss_weights)
        loss = add_linear_terms(loss, part, pred, target, batch["noisy"], cfg)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        if cfg.grad_norm:
            for p in model.parameters():
                if p.grad is not None:
                    p.grad /= p.grad.norm() + 1e-8
        opt.step()
        return loss.item(), part

    losses, parts, seconds, done = run_loop("nca", cfg, step_fn, 50, progress)
    result = TrainResult("nca", model, cfg, losses, parts, seconds, done,
                         data={"hash": ts.hash, "scenes": ts.scenes, **ts.config})
    if validation is not None:
        if cfg.select_from:
            chosen, table = select_iterations(model, validation, cfg.select_from,
                                              cfg.color_encoding, cfg.select_by,
                                              cfg.autoexposure, cfg.select_metric,
                                              cfg.select_per_spp, cfg.select_tolerance)
            if isinstance(chosen, dict):  # per sample count; the 1-spp count is the default
                result.data["iterations_by_spp"] = chosen
                chosen = chosen[min(chosen)]
            cfg = dataclasses.replace(cfg, iterations=chosen)
            result.config = cfg
            result.data["iterations_selection"] = table
        result.validation = validate_nca(model, validation, cfg.iterations, cfg.color_encoding,
                                         cfg.autoexposure)
    return result


def _rmse(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean((np.asarray(a, np.float64) - b) ** 2)))


def select_iterations(model, vs: TrainingSet, candidates, encoding: str = "log1p",
                      by: str = "worst", exposure: bool = False, metric: str = "rmse",
                      per_spp: bool = False, tolerance: float = 0.0
                      ) -> tuple[int | dict[int, int], dict]:
    """The step count whose error relative to the noisy input's over the held-out images is
    best: ``by="worst"`` the lowest worst case (ties: lowest mean), i.e. the count least likely
    to make an image worse than its input; ``by="mean"`` the lowest mean.

    ``metric``: "rmse" (output RMSE / noisy RMSE, linear) or "relmse" (relMSE with ε = 1e-2
    over the noisy input's, :func:`dbench.metrics.relmse`). ``per_spp``: one choice per sample
    count of the set (the inference step count then follows the frame's spp) instead of one
    over all of them. ``tolerance``: the fewest steps whose criterion is within that fraction
    of the best one's (each step costs a convolution of the whole image). Returns (k or
    {spp: k}, {k: {"mean", "worst"}} or {spp: that table})."""
    from ..metrics import relmse

    if by not in ("worst", "mean"):
        raise ValueError(f"by: expected 'worst' or 'mean', got {by!r}")
    if metric not in ("rmse", "relmse"):
        raise ValueError(f"metric: expected 'rmse' or 'relmse', got {metric!r}")

    def error(x, ref):
        return _rmse(x, ref) if metric == "rmse" else relmse(x, ref)

    ratios: dict[int, dict[int, list[float]]] = {}  # k -> spp -> per-image ratios
    with torch.no_grad():
        for k in candidates:
            ratios[k] = {}
            for p in range(len(vs.spp)):
                batch = full_images(vs, p, exposure)
                out = model(nca_state(batch, encoding), k, torch.from_numpy(batch["level"]))
                out = nca_prediction(out[:, :3], batch, encoding)
                lin = np.maximum(np.expm1(np.minimum(out.numpy(), 80.0)), 0).transpose(0, 2, 3, 1)
                ratios[k][int(vs.spp[p])] = [
                    error(lin[i], batch["reference"][i])
                    / max(error(batch["noisy"][i], batch["reference"][i]), 1e-12)
                    for i in range(vs.shape[0])]
    order = ("worst", "mean") if by == "worst" else ("mean", "worst")

    def pick(spps) -> tuple[int, dict[str, dict[str, float]]]:
        table = {}
        for k in candidates:
            rel = [r for n in spps for r in ratios[k][n]]
            table[str(k)] = {"mean": float(np.mean(rel)), "worst": float(np.max(rel))}
        best = min(candidates, key=lambda k: tuple(table[str(k)][o] for o in order))
        bound = table[str(best)][order[0]] * (1.0 + tolerance)
        fewest = min(k for k in candidates if table[str(k)][order[0]] <= bound)
        return int(fewest), table

    spps = [int(n) for n in vs.spp]
    if not per_spp:
        return pick(spps)
    chosen, tables = {}, {}
    for n in spps:
        chosen[n], tables[str(n)] = pick([n])
    return chosen, tables


def validate_nca(model, vs: TrainingSet, iterations: int, encoding: str = "log1p",
                 exposure: bool = False) -> dict[str, float]:
    """Spec loss on every full image and spp of a held-out set, plus the noisy input's loss."""
    with torch.no_grad():
        vals, base = [], []
        for p in range(len(vs.spp)):
            batch = full_images(vs, p, exposure)
            out = model(nca_state(batch, encoding), iterations,
                        torch.from_numpy(batch["level"]))[:, :3]
            out = nca_prediction(out, batch, encoding)
            t = torch.log1p(to_tensor(batch["reference"]))
            vals.append(float(L.nca_loss(out, t)[0]))
            base.append(float(L.nca_loss(torch.log1p(to_tensor(batch["noisy"])), t)[0]))
    return {"loss": float(np.mean(vals)), "noisy_input_loss": float(np.mean(base)),
            "iterations": iterations, "scenes": vs.scenes}
