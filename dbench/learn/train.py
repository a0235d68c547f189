"""Training loops of the learned denoisers, with fixed seeds, and the shipping of their weights.

* :func:`train_nca` — spec/nca.md §4-5: random iteration count per batch (loss only after the
  last step), loss MSE + 0.5 L_g on log1p RGB plus [dbench] 1.0 x the relative linear MSE
  (:func:`losses.relative_linear_mse`), Adam, per-parameter gradient normalisation; the
  inference step count is chosen on held-out scenes, worst case first
  (:func:`select_iterations`).
* :func:`train_autoencoder` — spec/autoencoder.md §3-4, stage 1: single frames (state reset,
  L_t = 0), loss 0.8 L1 + 0.1 HFEN on the log1p of the remodulated RGB plus [dbench] 0.5 x the
  relative linear MSE, Adam (β = 0.9, 0.99).
* :func:`finetune_autoencoder_sequences` — stage 2: 7-frame crops of camera-animated training
  sequences (:func:`~dbench.learn.dataset.build_sequence_set`) with the hidden state carried,
  per-frame weights and L_t, every other step a single-frame batch.
* Both models draw a quarter of their crops around visible lights
  (:func:`~dbench.learn.dataset.sample_batch`, ``light_fraction``).
* :func:`ship_nca`, :func:`ship_autoencoder` — ONNX file plus a JSON with the training
  configuration, data hash, final losses, wall time and machine.

Reproducibility: everything random comes from ``numpy.random.default_rng(seed)`` and
``torch.manual_seed(seed)``; with the same thread count on the same machine the loss curve is
identical (tests check it on tiny data).

Example (tiny, rendering-free):
    >>> from dbench.learn.dataset import synthetic_training_set
    >>> r = train_nca(synthetic_training_set(), NCAConfig(steps=2, batch=2, crop=16,
    ...                                                  k_min=2, k_max=3))
    >>> len(r.losses)
    2
"""
from __future__ import annotations

import dataclasses
import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np
import torch

from . import losses as L
from .dataset import TrainingSet, sample_batch

PACKAGE_METHODS = Path(__file__).resolve().parent.parent / "methods"


@dataclass
class NCAConfig:
    """Training settings of the NCA (spec/nca.md §4-5; dbench values where the seed is silent)."""

    seed: int = 0
    steps: int = 2000
    batch: int = 8
    crop: int = 64
    lr: float = 1e-3
    lr_decay_at: tuple[float, ...] = (0.5, 0.8)  # fractions of ``steps``; lr × 0.3 at each
    # spec/nca.md §4 suggests k ~ U{8..32} and 16 at inference. dbench trains k ~ U{1..6} and
    # picks the inference default from ``select_from`` by the held-out scenes' relative linear
    # RMSE, worst case first (:func:`select_iterations`): every step darkens the edges of
    # visible lights (log-space averaging), which RMSE punishes, and few steps keep 1280x720
    # well within the 300 ms budget on 2 CPU cores.
    k_min: int = 1
    k_max: int = 6
    iterations: int = 4  # inference default when no validation set selects one
    select_from: tuple[int, ...] = (1, 2, 3, 4, 6)
    select_by: str = "worst"
    update_channels: str = "all"
    activation: str = "sigmoid"
    color_encoding: str = "log1p"  # spec §3; "log1p_demodulated" is an option (codec.py)
    linear_weight: float = 0.0  # weight of losses.clamped_linear_mse (0: spec loss only)
    linear_clamp: float = 64.0
    # [dbench] + 1.0 x losses.relative_linear_mse (the output's linear MSE over the input's, per
    # crop): the spec's log-space loss alone let the automaton dim visible lights
    relative_weight: float = 1.0
    bias_init: float = -0.5
    w_init_std: float = 0.0
    grad_norm: bool = True
    spp_choices: tuple[int, ...] = (1, 2, 4, 8)
    light_fraction: float = 0.25  # share of crops around visible lights (dataset.sample_batch)
    loss_weights: dict = field(default_factory=lambda: dict(L.NCA_WEIGHTS))
    max_minutes: float | None = None
    threads: int = 1  # one thread: on a shared 2-core machine two threads ran 5-10x slower


@dataclass
class AEConfig:
    """Training settings of the recurrent autoencoder (spec/autoencoder.md §4)."""

    seed: int = 0
    steps: int = 6000
    batch: int = 4
    crop: int = 96
    lr: float = 1e-3
    betas: tuple[float, float] = (0.9, 0.99)
    lr_decay_at: tuple[float, ...] = (0.6, 0.85)
    width_scale: float = 0.5
    features: tuple[str, ...] = ("normal", "albedo", "depth")
    recurrent: bool = True
    residual: bool = True  # [dbench] output = input colour + correction (model.RecurrentAE)
    blend: bool = False  # [dbench] output = gated blend of input colour and prediction
    zero_recurrent_init: bool = True
    spp_choices: tuple[int, ...] = (1, 2, 4, 8)
    light_fraction: float = 0.25  # share of crops around visible lights (dataset.sample_batch)
    loss_weights: dict = field(default_factory=lambda: dict(L.AE_WEIGHTS))
    linear_weight: float = 0.0  # weight of losses.clamped_linear_mse (0: spec loss only)
    linear_clamp: float = 64.0
    # [dbench] + 0.5 x losses.relative_linear_mse: the spec loss (log space) alone left visible
    # lights dim and caustics flat, which linear RMSE punishes
    relative_weight: float = 0.5
    max_minutes: float | None = None
    threads: int = 1  # one thread: on a shared 2-core machine two threads ran 5-10x slower


@dataclass
class TrainResult:
    method: str
    model: torch.nn.Module
    config: Any
    losses: list[float]
    parts: list[dict[str, float]]
    seconds: float
    steps_done: int
    validation: dict[str, float] = field(default_factory=dict)
    data: dict[str, Any] = field(default_factory=dict)

    def summary(self, tail: int = 100) -> dict[str, Any]:
        tail = max(1, min(tail, len(self.losses)))
        parts = {k: float(np.mean([p[k] for p in self.parts[-tail:]])) for k in self.parts[-1]}
        return {"final_train_loss": float(np.mean(self.losses[-tail:])),
                "final_train_parts": parts, "averaged_over_last_steps": tail,
                "validation": self.validation, "steps_done": self.steps_done,
                "wall_s": round(self.seconds, 1)}


def _seed_everything(seed: int, threads: int) -> np.random.Generator:
    """Seed torch and NumPy, fix the thread count, and flush denormals to zero (without it,
    training on rendered images slows down about 10x on x86 CPUs)."""
    torch.manual_seed(seed)
    torch.set_num_threads(threads)
    torch.set_flush_denormal(True)
    return np.random.default_rng(seed)


def _lr_at(step: int, cfg) -> float:
    lr = cfg.lr
    for frac in cfg.lr_decay_at:
        if step >= frac * cfg.steps:
            lr *= 0.3
    return lr


def _t(x: np.ndarray) -> torch.Tensor:
    """(B, H, W, C) NumPy -> (B, C, H, W) tensor."""
    return torch.from_numpy(np.ascontiguousarray(x.transpose(0, 3, 1, 2)))


def _add_linear_terms(loss: torch.Tensor, part: dict[str, float], pred: torch.Tensor,
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
        rel = L.relative_linear_mse(pred, target, _t(noisy), cfg.linear_clamp)
        loss = loss + cfg.relative_weight * rel
        part["relative"] = rel.item()
    return loss


# ---------------------------------------------------------------------------------------------
# NCA


def _a_eff(albedo: torch.Tensor) -> torch.Tensor:
    return torch.where(albedo > 1e-3, albedo, torch.ones_like(albedo))


def nca_state(batch: dict[str, np.ndarray], encoding: str = "log1p") -> torch.Tensor:
    """(B, 9, h, w) initial state from a batch: encoded colour, normal, albedo (spec/nca.md §1;
    encodings as in ``methods/nca/codec.py``)."""
    color = _t(batch["noisy"])
    if encoding == "log1p_demodulated":
        color = color / _a_eff(_t(batch["albedo"]))
    return torch.cat([torch.log1p(color), _t(batch["normal"]), _t(batch["albedo"])], dim=1)


def nca_prediction(out_rgb: torch.Tensor, batch: dict[str, np.ndarray], encoding: str
                   ) -> torch.Tensor:
    """log1p of the (remodulated) output, compared with log1p(reference)."""
    if encoding == "log1p_demodulated":
        return torch.log1p(torch.expm1(out_rgb.clamp(max=20.0)) * _a_eff(_t(batch["albedo"])))
    return out_rgb


def _loop(name: str, cfg, step_fn: Callable[[int], tuple[float, dict]], log_every: int,
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


def train_nca(ts: TrainingSet, cfg: NCAConfig | None = None, progress: bool = False,
              validation: TrainingSet | None = None) -> TrainResult:
    """Train the 360-parameter automaton on crops of ``ts``."""
    from ..methods.nca.model import NCA

    cfg = cfg or NCAConfig()
    rng = _seed_everything(cfg.seed, cfg.threads)
    gen = torch.Generator().manual_seed(cfg.seed)
    model = NCA(cfg.update_channels, cfg.activation, cfg.bias_init, cfg.w_init_std,
                generator=gen)
    opt = torch.optim.Adam(model.parameters(), lr=cfg.lr)

    def step_fn(step: int):
        for g in opt.param_groups:
            g["lr"] = _lr_at(step, cfg)
        batch = sample_batch(ts, rng, cfg.batch, cfg.crop, cfg.spp_choices,
                             cfg.light_fraction)
        k = int(rng.integers(cfg.k_min, cfg.k_max + 1))
        out = model(nca_state(batch, cfg.color_encoding), k)[:, :3]
        pred = nca_prediction(out, batch, cfg.color_encoding)
        target = torch.log1p(_t(batch["reference"]))
        loss, part = L.nca_loss(pred, target, cfg.loss_weights)
        loss = _add_linear_terms(loss, part, pred, target, batch["noisy"], cfg)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        if cfg.grad_norm:
            for p in model.parameters():
                if p.grad is not None:
                    p.grad /= p.grad.norm() + 1e-8
        opt.step()
        return loss.item(), part

    losses, parts, seconds, done = _loop("nca", cfg, step_fn, 50, progress)
    result = TrainResult("nca", model, cfg, losses, parts, seconds, done,
                         data={"hash": ts.hash, "scenes": ts.scenes, **ts.config})
    if validation is not None:
        if cfg.select_from:
            chosen, table = select_iterations(model, validation, cfg.select_from,
                                              cfg.color_encoding, cfg.select_by)
            cfg = dataclasses.replace(cfg, iterations=chosen)
            result.config = cfg
            result.data["iterations_selection"] = table
        result.validation = validate_nca(model, validation, cfg.iterations, cfg.color_encoding)
    return result


def _rmse(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean((np.asarray(a, np.float64) - b) ** 2)))


def select_iterations(model, vs: TrainingSet, candidates, encoding: str = "log1p",
                      by: str = "worst") -> tuple[int, dict[str, dict[str, float]]]:
    """The step count whose relative linear RMSE (output RMSE / noisy RMSE) over every held-out
    image and spp is best: ``by="worst"`` the lowest worst case (ties: lowest mean), i.e. the
    count least likely to make an image worse than its input; ``by="mean"`` the lowest mean.
    Returns (k, {k: {"mean": ..., "worst": ...}})."""
    if by not in ("worst", "mean"):
        raise ValueError(f"by: expected 'worst' or 'mean', got {by!r}")
    table = {}
    with torch.no_grad():
        for k in candidates:
            rel = []
            for p in range(len(vs.spp)):
                batch = {"noisy": vs.noisy[:, p], "normal": vs.normal, "albedo": vs.albedo}
                out = nca_prediction(model(nca_state(batch, encoding), k)[:, :3], batch, encoding)
                lin = np.maximum(np.expm1(np.minimum(out.numpy(), 80.0)), 0).transpose(0, 2, 3, 1)
                for i in range(vs.shape[0]):
                    rel.append(_rmse(lin[i], vs.reference[i])
                               / max(_rmse(vs.noisy[i, p], vs.reference[i]), 1e-12))
            table[str(k)] = {"mean": float(np.mean(rel)), "worst": float(np.max(rel))}
    order = ("worst", "mean") if by == "worst" else ("mean", "worst")
    best = min(candidates, key=lambda k: tuple(table[str(k)][o] for o in order))
    return int(best), table


def validate_nca(model, vs: TrainingSet, iterations: int, encoding: str = "log1p"
                 ) -> dict[str, float]:
    """Spec loss on every full image and spp of a held-out set, plus the noisy input's loss."""
    with torch.no_grad():
        vals, base = [], []
        for p in range(len(vs.spp)):
            batch = {"noisy": vs.noisy[:, p], "normal": vs.normal, "albedo": vs.albedo}
            out = model(nca_state(batch, encoding), iterations)[:, :3]
            out = nca_prediction(out, batch, encoding)
            t = torch.log1p(_t(vs.reference))
            vals.append(float(L.nca_loss(out, t)[0]))
            base.append(float(L.nca_loss(torch.log1p(_t(vs.noisy[:, p])), t)[0]))
    return {"loss": float(np.mean(vals)), "noisy_input_loss": float(np.mean(base)),
            "iterations": iterations, "scenes": vs.scenes}


# ---------------------------------------------------------------------------------------------
# autoencoder


def ae_inputs(batch: dict[str, np.ndarray], features) -> tuple[torch.Tensor, torch.Tensor]:
    """Network input (B, C, h, w) and a_eff (B, 3, h, w), as ``autoencoder.model.encode``."""
    from ..methods.autoencoder.model import ALBEDO_EPS

    albedo = _t(batch["albedo"])
    a_eff = torch.where(albedo > ALBEDO_EPS, albedo, torch.ones_like(albedo))
    chans = [torch.log1p(_t(batch["noisy"]) / a_eff)]
    for f in features:
        chans.append(_t(batch[f]))
    return torch.cat(chans, 1), a_eff


def ae_prediction(y: torch.Tensor, a_eff: torch.Tensor) -> torch.Tensor:
    """log1p of the remodulated output (what the loss compares with log1p(reference))."""
    return torch.log1p(torch.expm1(y.clamp(max=20.0)) * a_eff)


def train_autoencoder(ts: TrainingSet, cfg: AEConfig | None = None, progress: bool = False,
                      validation: TrainingSet | None = None) -> TrainResult:
    """Train the recurrent autoencoder on single-frame crops of ``ts`` (state reset)."""
    from ..methods.autoencoder.model import RecurrentAE, in_channels_for

    cfg = cfg or AEConfig()
    rng = _seed_everything(cfg.seed, cfg.threads)
    model = RecurrentAE(in_channels_for(cfg.features), cfg.width_scale, cfg.recurrent,
                        cfg.residual and not cfg.blend, cfg.blend)
    if cfg.residual and not cfg.blend:  # start as the identity
        with torch.no_grad():
            model.out.weight.zero_()
            model.out.bias.zero_()
    if cfg.zero_recurrent_init:
        with torch.no_grad():
            for lvl, conv in enumerate(model.rec_b):
                conv.weight[:, model.enc_widths[lvl]:] = 0.0
    opt = torch.optim.Adam(model.parameters(), lr=cfg.lr, betas=cfg.betas)

    def step_fn(step: int):
        for g in opt.param_groups:
            g["lr"] = _lr_at(step, cfg)
        batch = sample_batch(ts, rng, cfg.batch, cfg.crop, cfg.spp_choices,
                             cfg.light_fraction)
        x, a_eff = ae_inputs(batch, cfg.features)
        y, _ = model(x)
        pred = ae_prediction(y, a_eff)[:, None]
        target = torch.log1p(_t(batch["reference"]))[:, None]
        loss, part = L.autoencoder_loss(pred, target, cfg.loss_weights)
        loss = _add_linear_terms(loss, part, pred[:, 0], target[:, 0], batch["noisy"], cfg)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        return loss.item(), part

    losses, parts, seconds, done = _loop("autoencoder", cfg, step_fn, 25, progress)
    result = TrainResult("autoencoder", model, cfg, losses, parts, seconds, done,
                         data={"hash": ts.hash, "scenes": ts.scenes, **ts.config})
    if validation is not None:
        result.validation = validate_autoencoder(model, validation, cfg.features)
    return result


@dataclass
class AESequenceConfig:
    """Second training stage of the autoencoder (spec/autoencoder.md §3-4): 7-frame sequences
    with the state carried, per-frame weights and the temporal loss, interleaved with
    single-frame steady batches so the state-reset quality is kept."""

    seed: int = 1
    steps: int = 1500
    batch: int = 2
    crop: int = 64
    frames: int = 7  # len(losses.FRAME_WEIGHTS)
    lr: float = 1e-3  # 2e-4 for 800 steps left the recurrent weights near zero
    betas: tuple[float, float] = (0.9, 0.99)
    lr_decay_at: tuple[float, ...] = (0.5, 0.8)
    steady_every: int = 2  # every n-th step is a single-frame steady batch (0: never)
    steady_batch: int = 4
    steady_crop: int = 96
    loss_weights: dict = field(default_factory=lambda: dict(L.AE_WEIGHTS))
    max_minutes: float | None = None
    threads: int = 1


def finetune_autoencoder_sequences(model, ss, cfg: AESequenceConfig, features,
                                   steady: TrainingSet | None = None,
                                   steady_cfg: AEConfig | None = None,
                                   progress: bool = False) -> dict[str, Any]:
    """Train ``model`` (in place) on crops of the :class:`~dbench.learn.dataset.SequenceSet`
    ``ss``: the hidden state is carried through ``cfg.frames`` frames and the loss is
    :func:`losses.autoencoder_loss` over the sequence (per-frame weights, L_t). Every
    ``steady_every``-th step uses a single-frame batch of ``steady`` instead (state reset,
    L_t = 0). ``steady_cfg``'s linear terms (:func:`_add_linear_terms`) are added on every
    frame, as in stage 1. Returns a summary for the shipped JSON: steps, wall time, loss curve and parts."""
    from .dataset import sample_sequence_batch

    rng = _seed_everything(cfg.seed, cfg.threads)
    steady_cfg = steady_cfg or AEConfig()
    opt = torch.optim.Adam(model.parameters(), lr=cfg.lr, betas=cfg.betas)

    def step_fn(step: int):
        for g in opt.param_groups:
            g["lr"] = _lr_at(step, cfg)
        use_steady = (steady is not None and cfg.steady_every > 0
                      and (step + 1) % cfg.steady_every == 0)
        if use_steady:
            one = sample_batch(steady, rng, cfg.steady_batch, cfg.steady_crop,
                               steady_cfg.spp_choices, steady_cfg.light_fraction)
            batch = {k: v[:, None] for k, v in one.items() if k != "spp"}
        else:
            batch = sample_sequence_batch(ss, rng, cfg.batch, cfg.crop, cfg.frames)
        hidden, preds, targets = None, [], []
        for f in range(batch["noisy"].shape[1]):
            frame = {k: v[:, f] for k, v in batch.items()}
            x, a_eff = ae_inputs(frame, features)
            y, hidden = model(x, hidden)
            preds.append(ae_prediction(y, a_eff))
            targets.append(torch.log1p(_t(frame["reference"])))
        pred, target = torch.stack(preds, 1), torch.stack(targets, 1)
        loss, part = L.autoencoder_loss(pred, target, cfg.loss_weights)
        # the stage-1 objective's extra terms, on every frame
        noisy = batch["noisy"].reshape(-1, *batch["noisy"].shape[2:])
        loss = _add_linear_terms(loss, part, pred.flatten(0, 1), target.flatten(0, 1), noisy,
                                 steady_cfg)
        part = {f"{'steady' if use_steady else 'seq'}_{k}": v for k, v in part.items()}
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        return loss.item(), part

    losses, parts, seconds, done = _loop("autoencoder (sequences)", cfg, step_fn, 25, progress)
    seq_losses = [l for l, p in zip(losses, parts) if "seq_l1" in p]
    tail = max(1, min(100, len(seq_losses)))
    keys = sorted({k for p in parts for k in p})
    mean_parts = {k: float(np.mean([p[k] for p in parts[-200:] if k in p] or [np.nan]))
                  for k in keys}
    return {"config": dataclasses.asdict(cfg), "steps_done": done, "wall_s": round(seconds, 1),
            "final_sequence_loss": float(np.mean(seq_losses[-tail:])) if seq_losses else None,
            "final_parts": mean_parts, "loss_curve": _curve(losses),
            "data": {"hash": ss.hash, "scenes": ss.scenes, **ss.config}}


def validate_autoencoder_sequences(model, ss, features, frames: int = 7) -> dict[str, float]:
    """Mean per-frame spec loss over every full held-out sequence and spp with the state
    carried, and with the state reset every frame (what the recurrence adds)."""
    from ..methods.autoencoder.model import MULTIPLE

    s, p_count, f_count, h, w, _ = ss.noisy.shape
    if h % MULTIPLE or w % MULTIPLE:
        return {}
    out = {}
    with torch.no_grad():
        for carried in (True, False):
            vals = []
            for p in range(p_count):
                hidden = None
                for f in range(min(frames, f_count)):
                    batch = {"noisy": ss.noisy[:, p, f], "normal": ss.normal[:, p, f],
                             "albedo": ss.albedo[:, p, f], "depth": ss.depth[:, p, f]}
                    x, a_eff = ae_inputs(batch, features)
                    y, hidden = model(x, hidden if carried else None)
                    pred = ae_prediction(y, a_eff)[:, None]
                    t = torch.log1p(_t(ss.reference[:, f]))[:, None]
                    vals.append(float(L.autoencoder_loss(pred, t)[0]))
            out["loss_state_carried" if carried else "loss_state_reset"] = float(np.mean(vals))
    out["scenes"] = ss.scenes
    return out


def validate_autoencoder(model, vs: TrainingSet, features) -> dict[str, float]:
    from ..methods.autoencoder.model import MULTIPLE

    s, h, w = vs.shape
    if h % MULTIPLE or w % MULTIPLE:
        return {}
    with torch.no_grad():
        vals, base = [], []
        for p in range(len(vs.spp)):
            batch = {"noisy": vs.noisy[:, p], "normal": vs.normal, "albedo": vs.albedo,
                     "depth": vs.depth}
            x, a_eff = ae_inputs(batch, features)
            pred = ae_prediction(model(x)[0], a_eff)[:, None]
            t = torch.log1p(_t(vs.reference))[:, None]
            vals.append(float(L.autoencoder_loss(pred, t)[0]))
            base.append(float(L.autoencoder_loss(torch.log1p(_t(vs.noisy[:, p]))[:, None],
                                                 t)[0]))
    return {"loss": float(np.mean(vals)), "noisy_input_loss": float(np.mean(base)),
            "scenes": vs.scenes}


# ---------------------------------------------------------------------------------------------
# shipping


def _machine() -> dict[str, Any]:
    from ..bench.machine import machine_info

    info = machine_info()
    return {"cpu": info["cpu"], "cores": info["cores"], "gpu": info["gpu"],
            "torch_threads": torch.get_num_threads(), "torch": torch.__version__}


def _curve(losses: list[float], points: int = 40) -> list[list[float]]:
    """(step, mean loss over the window) pairs, ``points`` windows."""
    n = len(losses)
    if n == 0:
        return []
    edges = np.linspace(0, n, min(points, n) + 1).astype(int)
    return [[int(b), float(np.mean(losses[a:b]))] for a, b in zip(edges[:-1], edges[1:])]


def _describe(result: TrainResult, extra: dict) -> dict[str, Any]:
    cfg = dataclasses.asdict(result.config)
    return {"method": result.method, "trained_on": "cpu" if not torch.cuda.is_available()
            else "cuda", "machine": _machine(), "training_config": cfg,
            "data": result.data, "losses": result.summary(), "loss_curve": _curve(result.losses),
            "created": time.strftime("%Y-%m-%d %H:%M:%S"), **extra}


def _readable(path: Path) -> None:
    """Shipped files are package data: readable by everyone (temporary files are 0600)."""
    os.chmod(path, 0o644)


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
            "data_hash": result.data.get("hash", "")}
    model = build_onnx(W, b, cfg.update_channels, cfg.activation, None, meta)
    with atomic_path(out / "nca.onnx", suffix=".tmp.onnx") as tmp:
        onnx.save(model, str(tmp))
    _readable(out / "nca.onnx")
    info = _describe(result, {
        "parameters": count_parameters(result.model), "iterations": cfg.iterations,
        "update_channels": cfg.update_channels, "activation": cfg.activation,
        "color_encoding": cfg.color_encoding, "W": W.tolist(), "b": b.tolist()})
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
            "in_channels": str(net.in_channels), "data_hash": result.data.get("hash", "")}
    model = build_onnx(state, net.in_channels, net.enc_widths, stateful=True, metadata=meta,
                       residual=net.residual, blend=net.blend)
    with atomic_path(out / "autoencoder.onnx", suffix=".tmp.onnx") as tmp:
        onnx.save(model, str(tmp))
    _readable(out / "autoencoder.onnx")
    info = _describe(result, {
        "parameters": count_parameters(net), "in_channels": net.in_channels,
        "features": list(cfg.features), "width_scale": cfg.width_scale,
        "enc_widths": list(net.enc_widths), "dec_widths": list(net.dec_widths),
        "recurrent": cfg.recurrent, "residual": net.residual, "blend": net.blend})
    write_json(out / "autoencoder.json", info)
    _readable(out / "autoencoder.json")
    return out / "autoencoder.onnx", out / "autoencoder.json"


def split(ts: TrainingSet, n_validation: int) -> tuple[TrainingSet, TrainingSet | None]:
    """The last ``n_validation`` scenes held out for validation."""
    if n_validation <= 0:
        return ts, None
    s = ts.shape[0]
    if n_validation >= s:
        raise ValueError(f"n_validation: {n_validation} leaves no training scene of {s}")

    def part(sl: slice) -> TrainingSet:
        return TrainingSet(noisy=ts.noisy[sl], spp=ts.spp, reference=ts.reference[sl],
                           albedo=ts.albedo[sl], normal=ts.normal[sl], depth=ts.depth[sl],
                           scenes=ts.scenes[sl], config={**ts.config, "hash_full": ts.hash})

    return part(slice(0, s - n_validation)), part(slice(s - n_validation, s))


def run_training(method: str, *, n_scenes: int = 48, res: int = 128, ref_spp: int = 1024,
                 n_validation: int | None = None, cache=None, out_dir=None,
                 progress: bool = True, sequences: int = 0,
                 sequence_overrides: dict | None = None,
                 **overrides) -> tuple[TrainResult, tuple[Path, Path]]:
    """What ``dbench train`` runs: build (or read) the training set, train, ship.

    ``sequences`` (autoencoder only): after the single-frame stage, render that many training
    sequences (:func:`~dbench.learn.dataset.build_sequence_set`; the last 2 held out) and train
    the recurrence on them (:func:`finetune_autoencoder_sequences`, settings
    :class:`AESequenceConfig` updated by ``sequence_overrides``)."""
    from .dataset import build_training_set

    if method not in ("nca", "autoencoder"):
        from ..errors import UnknownNameError
        raise UnknownNameError(f"unknown trainable method {method!r}; available: "
                               "autoencoder, nca")
    if progress:
        print(f"training set: {n_scenes} procedural scenes at {res} px, reference {ref_spp} spp")
    ts = build_training_set(n_scenes=n_scenes, res=res, ref_spp=ref_spp, cache=cache,
                            progress=progress)
    if n_validation is None:  # the NCA picks its step count on the held-out scenes: 4 of them
        n_validation = 4 if method == "nca" else 2
    train_set, val_set = split(ts, n_validation)
    if method == "nca":
        cfg = dataclasses.replace(NCAConfig(), **overrides)
        result = train_nca(train_set, cfg, progress, val_set)
        paths = ship_nca(result, out_dir)
    else:
        cfg = dataclasses.replace(AEConfig(), **overrides)
        result = train_autoencoder(train_set, cfg, progress, val_set)
        if sequences:
            from .dataset import build_sequence_set, split_sequences

            if progress:
                print(f"training sequences: {sequences} camera animations of training scenes")
            seq_train, seq_val = split_sequences(
                build_sequence_set(n_sequences=sequences, cache=cache, progress=progress), 2)
            scfg = dataclasses.replace(AESequenceConfig(), **(sequence_overrides or {}))
            stage = finetune_autoencoder_sequences(result.model, seq_train, scfg, cfg.features,
                                                   train_set, cfg, progress)
            stage["validation"] = validate_autoencoder_sequences(result.model, seq_val,
                                                                 cfg.features, scfg.frames)
            result.data["sequence_stage"] = stage
            result.seconds += stage["wall_s"]
            if val_set is not None:
                result.validation = validate_autoencoder(result.model, val_set, cfg.features)
        paths = ship_autoencoder(result, out_dir)
    if progress:
        print(json.dumps(result.summary(), indent=1, default=str))
        print(f"wrote {paths[0]} and {paths[1]}")
    return result, paths
