"""The pieces every training loop shares: seeding, the learning-rate schedule, NumPy → tensor,
the relative linear loss term, the logged loop itself and the loss curve of a record."""
from __future__ import annotations

import time
from typing import Callable

import numpy as np
import torch

from . import losses as L


def seed_everything(seed: int, threads: int) -> np.random.Generator:
    """Seed torch and NumPy, fix the thread count, and flush denormals to zero (without it,
    training on rendered images slows down about 10x on x86 CPUs)."""
    torch.manual_seed(seed)
    torch.set_num_threads(threads)
    torch.set_flush_denormal(True)
    return np.random.default_rng(seed)


def lr_at(step: int, cfg) -> float:
    lr = cfg.lr
    for frac in cfg.lr_decay_at:
        if step >= frac * cfg.steps:
            lr *= 0.3
    return lr


def make_optimizer(model: torch.nn.Module, lr: float, fast, fast_lr: float,
                   betas: tuple[float, float] = (0.9, 0.999)) -> torch.optim.Adam:
    """Adam over ``model``; the parameters whose name satisfies ``fast(name)`` (a step-size
    gate's two numbers) in a group of their own at ``fast_lr``: Adam moves a parameter by about
    lr per step, and at the network's lr such scalars could move by only a few units in a whole
    run. Each group's ``lr_scale`` is its lr over ``lr``; :func:`set_lr` keeps the ratio."""
    named = list(model.named_parameters())
    groups = [{"params": [p for n, p in named if not fast(n)], "lr_scale": 1.0}]
    quick = [p for n, p in named if fast(n)]
    if quick:
        groups.append({"params": quick, "lr_scale": fast_lr / lr})
    return torch.optim.Adam(groups, lr=lr, betas=betas)


def set_lr(opt: torch.optim.Optimizer, lr: float) -> None:
    """Every group of ``opt`` at ``lr`` times its ``lr_scale`` (:func:`make_optimizer`)."""
    for g in opt.param_groups:
        g["lr"] = lr * g.get("lr_scale", 1.0)


def to_tensor(x: np.ndarray) -> torch.Tensor:
    """(B, H, W, C) NumPy -> (B, C, H, W) tensor."""
    return torch.from_numpy(np.ascontiguousarray(x.transpose(0, 3, 1, 2)))


def add_linear_terms(loss: torch.Tensor, part: dict[str, float], pred: torch.Tensor,
                      target: torch.Tensor, noisy: np.ndarray, cfg) -> torch.Tensor:
    """``loss`` plus the [dbench] linear-radiance terms a config asks for
    (``linear_weight`` x :func:`losses.clamped_linear_mse`, ``relative_weight`` x
    :func:`losses.relative_linear_mse`), their values recorded in ``part``. ``pred`` and
    ``target`` (N, 3, h, w) are log1p-encoded; ``noisy`` (N, h, w, 3) is the linear input."""
    if cfg.linear_weight:
        lin = L.clamped_linear_mse(pred, target, cfg.linear_clamp)
        loss = loss + cfg.linear_weight * lin
        part["linear"] = lin.item()
    if cfg.relative_weight:
        rel = L.relative_linear_mse(pred, target, to_tensor(noisy), cfg.linear_clamp,
                                    cfg.relative_eps, cfg.relative_metric)
        loss = loss + cfg.relative_weight * rel
        part["relative"] = rel.item()
    return loss


def run_loop(name: str, cfg, step_fn: Callable[[int], tuple[float, dict]], log_every: int,
          progress: bool) -> tuple[list[float], list[dict], float, int]:
    losses, parts = [], []
    t0 = time.perf_counter()
    done = 0
    for step in range(cfg.steps):
        if cfg.max_minutes is not None and time.perf_counter() - t0 > 60 * cfg.max_minutes:
            break
        loss, part = step_fn(step)
        losses.append(loss)
        parts.append(part)
        done = step + 1
        if progress and (step % log_every == 0 or step == cfg.steps - 1):
            recent = np.mean(losses[-log_every:])
            print(f"  {name} step {step:5d}  loss {recent:.5f}  "
                  f"{time.perf_counter() - t0:6.0f} s", flush=True)
    return losses, parts, time.perf_counter() - t0, done


def loss_curve(losses: list[float], points: int = 40) -> list[list[float]]:
    """(step, mean loss over the window) pairs, ``points`` windows."""
    n = len(losses)
    if n == 0:
        return []
    edges = np.linspace(0, n, min(points, n) + 1).astype(int)
    return [[int(b), float(np.mean(losses[a:b]))] for a, b in zip(edges[:-1], edges[1:])]
