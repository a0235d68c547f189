"""Training the ``autoencoder`` denoiser (docs/methods/autoencoder.md §3-4): stage 1 on single frames
(:func:`train_autoencoder`), stage 2 on 7-frame crops of camera-animated sequences with the
hidden state carried (:func:`finetune_autoencoder_sequences`), and their validations."""
from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import torch

from . import losses as L
from .configs import AEConfig, AEConsistencyConfig, AESequenceConfig, TrainResult
from ..methods.kernels.hdr_input import autoexposure, noise_level
from .dataset import TrainingSet, full_images, sample_batch
from .loop import (add_linear_terms, loss_curve, lr_at, make_optimizer, run_loop,
                   seed_everything, set_lr, to_tensor)


def ae_inputs(batch: dict[str, np.ndarray], features) -> tuple[torch.Tensor, torch.Tensor]:
    """Network input (B, C, h, w) and a_eff (B, 3, h, w), as ``autoencoder.model.encode``."""
    from ..methods.autoencoder.model import ALBEDO_EPS

    albedo = to_tensor(batch["albedo"])
    a_eff = torch.where(albedo > ALBEDO_EPS, albedo, torch.ones_like(albedo))
    chans = [torch.log1p(to_tensor(batch["noisy"]) / a_eff)]
    for f in features:
        if f == "level":  # (B,) noise levels as constant planes
            lv = torch.as_tensor(np.asarray(batch["level"], np.float32))
            chans.append(lv[:, None, None, None].expand(-1, 1, *albedo.shape[2:]))
        else:
            chans.append(to_tensor(batch[f]))
    return torch.cat(chans, 1), a_eff


def ae_prediction(y: torch.Tensor, a_eff: torch.Tensor) -> torch.Tensor:
    """log1p of the remodulated output (what the loss compares with log1p(reference))."""
    return torch.log1p(torch.expm1(y.clamp(max=20.0)) * a_eff)


def level_channel(features) -> int | None:
    """Index of the ``level`` plane in the network input (None without it)."""
    from ..methods.autoencoder.model import in_channels_for

    features = list(features)
    return in_channels_for(features[:features.index("level")]) if "level" in features else None


def _is_level_gate(name: str) -> bool:
    return name == "level_gate"


def train_autoencoder(ts: TrainingSet, cfg: AEConfig | None = None, progress: bool = False,
                      validation: TrainingSet | None = None) -> TrainResult:
    """Train the recurrent autoencoder on single-frame crops of ``ts`` (state reset)."""
    from ..methods.autoencoder.model import RecurrentAE, in_channels_for

    cfg = cfg or AEConfig()
    rng = seed_everything(cfg.seed, cfg.threads)
    residual = cfg.residual and not cfg.blend
    gate = level_channel(cfg.features) if cfg.level_gate and residual else None
    model = RecurrentAE(in_channels_for(cfg.features), cfg.width_scale, cfg.recurrent,
                        residual, cfg.blend, gate, cfg.gate_max, tuple(cfg.gate_init),
                        cfg.pixel_gate and residual)
    if residual:  # start as the identity
        with torch.no_grad():
            model.out.weight.zero_()
            model.out.bias.zero_()
    if cfg.zero_recurrent_init:
        with torch.no_grad():
            for lvl, conv in enumerate(model.rec_b):
                conv.weight[:, model.enc_widths[lvl]:] = 0.0
    opt = make_optimizer(model, cfg.lr, _is_level_gate, cfg.gate_lr, cfg.betas)

    def step_fn(step: int):
        set_lr(opt, lr_at(step, cfg))
        batch = sample_batch(ts, rng, cfg.batch, cfg.crop, cfg.spp_choices,
                             cfg.light_fraction, cfg.mix_spp, cfg.autoexposure)
        x, a_eff = ae_inputs(batch, cfg.features)
        y, _ = model(x)
        pred = ae_prediction(y, a_eff)[:, None]
        target = torch.log1p(to_tensor(batch["reference"]))[:, None]
        loss, part = L.autoencoder_loss(pred, target, cfg.loss_weights)
        loss = add_linear_terms(loss, part, pred[:, 0], target[:, 0], batch["noisy"], cfg)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        return loss.item(), part

    losses, parts, seconds, done = run_loop("autoencoder", cfg, step_fn, 25, progress)
    result = TrainResult("autoencoder", model, cfg, losses, parts, seconds, done,
                         data={"hash": ts.hash, "scenes": ts.scenes, **ts.config})
    if validation is not None:
        result.validation = validate_autoencoder(model, validation, cfg.features,
                                                 cfg.autoexposure)
    return result


def finetune_autoencoder_sequences(model, ss, cfg: AESequenceConfig, features,
                                   steady: TrainingSet | None = None,
                                   steady_cfg: AEConfig | None = None,
                                   progress: bool = False) -> dict[str, Any]:
    """Train ``model`` (in place) on crops of the :class:`~dbench.learn.dataset.SequenceSet`
    ``ss``: the hidden state is carried through ``cfg.frames`` frames and the loss is
    :func:`losses.autoencoder_loss` over the sequence (per-frame weights, L_t). Every
    ``steady_every``-th step uses a single-frame batch of ``steady`` instead (state reset,
    L_t = 0). ``steady_cfg``'s linear terms (:func:`add_linear_terms`) are added on every
    frame, as in stage 1. Returns a summary for the shipped JSON: steps, wall time, loss curve and parts."""
    from .dataset import sample_sequence_batch

    rng = seed_everything(cfg.seed, cfg.threads)
    steady_cfg = steady_cfg or AEConfig()
    gate_lr = cfg.lr * steady_cfg.gate_lr / steady_cfg.lr  # stage 1's ratio to the network's lr
    opt = make_optimizer(model, cfg.lr, _is_level_gate, gate_lr, cfg.betas)

    def step_fn(step: int):
        set_lr(opt, lr_at(step, cfg))
        use_steady = (steady is not None and cfg.steady_every > 0
                      and (step + 1) % cfg.steady_every == 0)
        if use_steady:
            one = sample_batch(steady, rng, cfg.steady_batch, cfg.steady_crop,
                               steady_cfg.spp_choices, steady_cfg.light_fraction,
                               steady_cfg.mix_spp, steady_cfg.autoexposure)
            batch = {k: v[:, None] for k, v in one.items() if k != "spp"}
        else:
            batch = sample_sequence_batch(ss, rng, cfg.batch, cfg.crop, cfg.frames,
                                          steady_cfg.autoexposure)
        hidden, preds, targets = None, [], []
        for f in range(batch["noisy"].shape[1]):
            frame = {k: v[:, f] for k, v in batch.items()}
            x, a_eff = ae_inputs(frame, features)
            y, hidden = model(x, hidden)
            preds.append(ae_prediction(y, a_eff))
            targets.append(torch.log1p(to_tensor(frame["reference"])))
        pred, target = torch.stack(preds, 1), torch.stack(targets, 1)
        loss, part = L.autoencoder_loss(pred, target, cfg.loss_weights)
        # the stage-1 objective's extra terms, on every frame
        noisy = batch["noisy"].reshape(-1, *batch["noisy"].shape[2:])
        loss = add_linear_terms(loss, part, pred.flatten(0, 1), target.flatten(0, 1), noisy,
                                 steady_cfg)
        part = {f"{'steady' if use_steady else 'seq'}_{k}": v for k, v in part.items()}
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        return loss.item(), part

    losses, parts, seconds, done = run_loop("autoencoder (sequences)", cfg, step_fn, 25, progress)
    seq_losses = [l for l, p in zip(losses, parts) if "seq_l1" in p]
    tail = max(1, min(100, len(seq_losses)))
    keys = sorted({k for p in parts for k in p})
    mean_parts = {k: float(np.mean([p[k] for p in parts[-200:] if k in p] or [np.nan]))
                  for k in keys}
    return {"config": dataclasses.asdict(cfg), "steps_done": done, "wall_s": round(seconds, 1),
            "final_sequence_loss": float(np.mean(seq_losses[-tail:])) if seq_losses else None,
            "final_parts": mean_parts, "loss_curve": loss_curve(losses),
            "data": {"hash": ss.hash, "scenes": ss.scenes, **ss.config}}


def consistency_stage(model, ss, ts: TrainingSet, cfg: AEConsistencyConfig, ae_cfg: AEConfig,
                      progress: bool = False) -> dict[str, Any]:
    """Stage 3 (:class:`AEConsistencyConfig`): :func:`finetune_autoencoder_sequences` of
    ``model`` in place on the sequences ``ss`` and the single frames ``ts`` (built with
    ``cfg.features_with``), its relative term replaced by ``cfg``'s. Returns the stage's record
    (as stage 2's, plus this configuration)."""
    seq_cfg = AESequenceConfig(seed=cfg.seed, steps=cfg.steps, lr=cfg.lr,
                               lr_decay_at=tuple(cfg.lr_decay_at), max_minutes=cfg.max_minutes,
                               threads=cfg.threads)
    loss_cfg = dataclasses.replace(ae_cfg, relative_weight=cfg.relative_weight,
                                   relative_eps=cfg.relative_eps,
                                   relative_metric=cfg.relative_metric)
    stage = finetune_autoencoder_sequences(model, ss, seq_cfg, ae_cfg.features, ts, loss_cfg,
                                           progress)
    stage["config"] = {**dataclasses.asdict(cfg), "sequence_schedule": stage["config"]}
    stage["steady_data"] = {"hash": ts.hash, **ts.config}
    return stage


def validate_autoencoder_sequences(model, ss, features, frames: int = 7,
                                   exposure: bool = False) -> dict[str, float]:
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
                    e = np.array([autoexposure(x) if exposure else 1.0
                                  for x in ss.noisy[:, p, f]], np.float32)[:, None, None, None]
                    batch = {"noisy": ss.noisy[:, p, f] * e, "normal": ss.normal[:, p, f],
                             "albedo": ss.albedo[:, p, f], "depth": ss.depth[:, p, f],
                             "level": np.full(s, noise_level(ss.spp[p]), np.float32)}
                    x, a_eff = ae_inputs(batch, features)
                    y, hidden = model(x, hidden if carried else None)
                    pred = ae_prediction(y, a_eff)[:, None]
                    t = torch.log1p(to_tensor(ss.reference[:, f] * e))[:, None]
                    vals.append(float(L.autoencoder_loss(pred, t)[0]))
            out["loss_state_carried" if carried else "loss_state_reset"] = float(np.mean(vals))
    out["scenes"] = ss.scenes
    return out


def validate_autoencoder(model, vs: TrainingSet, features, exposure: bool = False
                         ) -> dict[str, float]:
    from ..methods.autoencoder.model import MULTIPLE

    s, h, w = vs.shape
    if h % MULTIPLE or w % MULTIPLE:
        return {}
    with torch.no_grad():
        vals, base = [], []
        for p in range(len(vs.spp)):
            batch = full_images(vs, p, exposure)
            x, a_eff = ae_inputs(batch, features)
            pred = ae_prediction(model(x)[0], a_eff)[:, None]
            t = torch.log1p(to_tensor(batch["reference"]))[:, None]
            vals.append(float(L.autoencoder_loss(pred, t)[0]))
            base.append(float(L.autoencoder_loss(torch.log1p(to_tensor(batch["noisy"]))[:, None],
                                                 t)[0]))
    return {"loss": float(np.mean(vals)), "noisy_input_loss": float(np.mean(base)),
            "scenes": vs.scenes}
