"""Training loops of the learned denoisers, with fixed seeds, and the shipping of their weights:
``dbench train`` (:func:`run_training`) on the pieces of ``configs.py``, ``loop.py``,
``train_nca.py``, ``train_autoencoder.py`` and ``ship.py``, all exposed here.

* :func:`train_nca` — docs/methods/nca.md §4-5: random iteration count per batch (loss only after the
  last step), loss MSE + 0.5 L_g on log1p RGB plus [dbench] 1.0 x the relative linear MSE
  (:func:`losses.relative_linear_mse`), Adam, per-parameter gradient normalisation; the
  inference step count is chosen on held-out scenes, worst case first
  (:func:`select_iterations`).
* :func:`train_autoencoder` — docs/methods/autoencoder.md §3-4, stage 1: single frames (state reset,
  L_t = 0), loss 0.8 L1 + 0.1 HFEN on the log1p of the remodulated RGB plus [dbench] 0.5 x the
  relative linear MSE, Adam (β = 0.9, 0.99).
* :func:`finetune_autoencoder_sequences` — stage 2: 7-frame crops of camera-animated training
  sequences (:func:`~dbench.learn.dataset.build_sequence_set`) with the hidden state carried,
  per-frame weights and L_t, every other step a single-frame batch.
* :func:`consistency_stage` — [dbench] stage 3 (:class:`AEConsistencyConfig`): stage 2's
  alternation at a lower lr, the relative term measured in relMSE with ε = 1e-6 so that every
  crop, the nearly converged ones included, asks the output to beat its input; the single frames
  carry features from the highest-spp render. ``from_weights`` runs it alone on shipped weights.
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
from pathlib import Path

import numpy as np

from .configs import AEConfig, AEConsistencyConfig, AESequenceConfig, NCAConfig, TrainResult
from .dataset import TrainingSet
from .ship import machine_record, ship_autoencoder, ship_nca
from .train_autoencoder import (consistency_stage, finetune_autoencoder_sequences,
                                train_autoencoder, validate_autoencoder,
                                validate_autoencoder_sequences)
from .train_nca import select_iterations, train_nca, validate_nca


#: Sample counts rendered for every training scene (independent seeds); sums of subsets give
#: every count from 1 to 1375 (:func:`~dbench.learn.dataset.mixed_spp`).
TRAINING_SPP = (1, 2, 4, 8, 16, 64, 256, 1024)


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


def resume_autoencoder(weights: str | Path) -> TrainResult:
    """A :class:`TrainResult` holding the shipped autoencoder ``weights`` (ONNX) as a PyTorch
    model, with the configuration, data record and stage-1 losses of the JSON beside it (the
    stage-1 record stands for the resumed run's; ``previous``)."""
    import onnx
    import torch

    from ..errors import DbenchInputError
    from ..methods.autoencoder.export import state_from_onnx
    from ..methods.autoencoder.model import RecurrentAE

    weights = Path(weights)
    record = weights.with_suffix(".json")
    if not weights.is_file() or not record.is_file():
        raise DbenchInputError(f"--from-weights: expected an autoencoder .onnx with its .json "
                               f"beside it, got {weights}")
    try:
        prev = json.loads(record.read_text(encoding="utf-8"))
        if prev.get("method") not in (None, "autoencoder"):
            raise ValueError(f"it records a {prev.get('method')} model")
        fields = {f.name for f in dataclasses.fields(AEConfig)}
        cfg = AEConfig(**{k: tuple(v) if isinstance(v, list) else v
                          for k, v in prev["training_config"].items() if k in fields})
        residual = cfg.residual and not cfg.blend
        net = RecurrentAE(int(prev["in_channels"]), cfg.width_scale, cfg.recurrent, residual,
                          cfg.blend, None, cfg.gate_max, tuple(cfg.gate_init),
                          bool(prev.get("pixel_gate")) and residual)
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
        raise DbenchInputError(f"--from-weights: {record} is not the training record of an "
                               f"autoencoder ({_reason(exc)})") from None
    if prev.get("level_gate"):
        raise DbenchInputError("--from-weights: a level-gated model cannot be resumed")
    try:
        net.load_state_dict({k: torch.from_numpy(np.array(v))  # writable copies
                             for k, v in state_from_onnx(onnx.load(str(weights))).items()})
    except Exception as exc:  # noqa: BLE001 - onnx's DecodeError, torch's shape mismatch, ...
        raise DbenchInputError(f"--from-weights: {weights} does not hold the weights its "
                               f"{record.name} describes ({_reason(exc)})") from None
    losses = prev.get("losses", {})
    return TrainResult("autoencoder", net, cfg, [], [], float(losses.get("wall_s", 0.0)),
                       int(losses.get("steps_done", 0)), dict(losses.get("validation", {})),
                       dict(prev.get("data", {})), previous=prev)


#: Training scenes held out for validation where ``n_validation`` is not given (the NCA picks
#: its step count on them), and training sequences held out (:func:`split_sequences`).
HELD_OUT = {"nca": 4, "autoencoder": 2}
SEQUENCES_HELD_OUT = 2


def check_training(method: str, *, n_scenes: int, res: int, sequences: int = 0,
                   n_validation: int | None = None, sequence_overrides: dict | None = None,
                   **overrides) -> None:
    """Refuse, before anything renders, the settings :func:`run_training` could not finish
    with: a DbenchInputError naming the ``dbench train`` option and the valid range. The
    training images must hold the method's largest crop; the scenes and sequences must leave
    one to train on after those held out; ``steps``, ``max_minutes`` and ``width_scale`` must
    be positive (0 steps trains nothing, and a width scale of 0 builds no network)."""
    import math

    from ..errors import DbenchInputError, UnknownNameError
    from ..resolution import MAX_SIDE

    def whole(value) -> bool:
        return isinstance(value, (int, np.integer)) and not isinstance(value, bool)

    if method not in HELD_OUT:
        raise UnknownNameError(f"unknown trainable method {method!r}; available: "
                               "autoencoder, nca")
    held = HELD_OUT[method] if n_validation is None else n_validation
    if not whole(n_scenes) or n_scenes < held + 1:
        raise DbenchInputError(f"--scenes: {method} holds {held} out for validation; expected "
                               f"an integer >= {held + 1}, got {n_scenes!r}")
    crop = overrides.get("crop", (NCAConfig() if method == "nca" else AEConfig()).crop)
    if method == "autoencoder" and sequences:  # stages 2-3 crop the single frames too
        crop = max(crop, (sequence_overrides or {}).get("steady_crop",
                                                        AESequenceConfig().steady_crop))
    if not whole(res) or not crop <= res <= MAX_SIDE:
        raise DbenchInputError(f"--res: {method} trains on {crop} px crops of the training "
                               f"images; expected an integer in [{crop}, {MAX_SIDE}], got "
                               f"{res!r}")
    if not whole(sequences) or sequences < 0 or (method == "nca" and sequences):
        raise DbenchInputError(f"--sequences: expected 0 or an integer >= "
                               f"{SEQUENCES_HELD_OUT + 1}, got {sequences!r}"
                               if method == "autoencoder" else
                               "--sequences: only the autoencoder is recurrent")
    if 0 < sequences <= SEQUENCES_HELD_OUT:
        raise DbenchInputError(f"--sequences: {SEQUENCES_HELD_OUT} of them are held out for "
                               f"validation; expected 0 (single frames only) or an integer >= "
                               f"{SEQUENCES_HELD_OUT + 1}, got {sequences}")
    steps = overrides.get("steps")
    if steps is not None and (not whole(steps) or steps < 1):
        raise DbenchInputError(f"--steps: expected an integer >= 1, got {steps!r}")
    for key, option in (("max_minutes", "--minutes"), ("width_scale", "--width-scale")):
        value = overrides.get(key)
        if value is not None and not (isinstance(value, (int, float)) and math.isfinite(value)
                                      and value > 0):
            raise DbenchInputError(f"{option}: expected a number > 0, got {value!r}")
    if "width_scale" in overrides and method != "autoencoder":
        raise DbenchInputError("--width-scale: only the autoencoder has widths")


def _reason(exc: Exception) -> str:
    """``exc`` on one short line, for a refusal."""
    text = " ".join(str(exc).split())
    return f"{type(exc).__name__}: {text[:200]}" if text else type(exc).__name__


def run_training(method: str, *, n_scenes: int = 48, res: int = 128, ref_spp: int = 2048,
                 spp: tuple[int, ...] = TRAINING_SPP,
                 n_validation: int | None = None, cache=None, out_dir=None,
                 progress: bool = True, sequences: int = 0,
                 sequence_overrides: dict | None = None, consistency: bool = True,
                 consistency_overrides: dict | None = None, from_weights=None,
                 **overrides) -> tuple[TrainResult, tuple[Path, Path]]:
    """What ``dbench train`` runs: build (or read) the training set, train, ship.

    ``sequences`` (autoencoder only): after the single-frame stage, render that many training
    sequences (:func:`~dbench.learn.dataset.build_sequence_set`; the last 2 held out) and train
    the recurrence on them (:func:`finetune_autoencoder_sequences`, settings
    :class:`AESequenceConfig` updated by ``sequence_overrides``); then, with ``consistency``,
    stage 3 (:func:`consistency_stage`, :class:`AEConsistencyConfig` updated by
    ``consistency_overrides``). ``from_weights`` (autoencoder): start from a shipped model and
    run stage 3 only (:func:`resume_autoencoder`)."""
    from .dataset import build_training_set

    check_training(method, n_scenes=n_scenes, res=res, sequences=sequences,
                   n_validation=n_validation, sequence_overrides=sequence_overrides, **overrides)
    if from_weights is not None and (method != "autoencoder" or not sequences or overrides
                                     or not consistency):
        from ..errors import DbenchInputError
        raise DbenchInputError("--from-weights: autoencoder only, with sequences, and without "
                               "stage-1 settings (they are the shipped model's)")
    # the weights are read before anything renders: a file that is not such a model is refused
    resumed = resume_autoencoder(from_weights) if from_weights is not None else None
    if progress:
        print(f"training set: {n_scenes} procedural scenes at {res} px, reference {ref_spp} spp")
    ts = build_training_set(n_scenes=n_scenes, res=res, spp=spp, ref_spp=ref_spp, cache=cache,
                            progress=progress) if from_weights is None else None
    if n_validation is None:  # the NCA picks its step count on the held-out scenes: 4 of them
        n_validation = HELD_OUT[method]
    if method == "nca":
        train_set, val_set = split(ts, n_validation)
        cfg = dataclasses.replace(NCAConfig(), **overrides)
        result = train_nca(train_set, cfg, progress, val_set)
        paths = ship_nca(result, out_dir)
    else:
        if from_weights is None:
            train_set, val_set = split(ts, n_validation)
            cfg = dataclasses.replace(AEConfig(), **overrides)
            result = train_autoencoder(train_set, cfg, progress, val_set)
        else:
            result = resumed
            cfg = result.config
        if sequences:
            from .dataset import build_sequence_set, split_sequences

            if progress:
                print(f"training sequences: {sequences} camera animations of training scenes")
            seq_train, seq_val = split_sequences(
                build_sequence_set(n_sequences=sequences, cache=cache, progress=progress), 2)
            scfg = dataclasses.replace(AESequenceConfig(), **(sequence_overrides or {}))
            if from_weights is None:
                stage = finetune_autoencoder_sequences(result.model, seq_train, scfg,
                                                       cfg.features, train_set, cfg, progress)
                stage["validation"] = validate_autoencoder_sequences(
                    result.model, seq_val, cfg.features, scfg.frames, cfg.autoexposure)
                result.data["sequence_stage"] = stage
                result.seconds += stage["wall_s"]
            if consistency:
                ccfg = dataclasses.replace(AEConsistencyConfig(),
                                           **(consistency_overrides or {}))
                if progress:
                    print(f"stage 3: single frames with features of the "
                          f"{ccfg.features_with} render")
                late = build_training_set(n_scenes=n_scenes, res=res, spp=spp,
                                          ref_spp=ref_spp, cache=cache, progress=progress,
                                          features_with=ccfg.features_with)
                late_train, late_val = split(late, n_validation)
                stage = consistency_stage(result.model, seq_train, late_train, ccfg, cfg,
                                          progress)
                stage["machine"] = machine_record()
                stage["validation"] = validate_autoencoder_sequences(
                    result.model, seq_val, cfg.features, scfg.frames, cfg.autoexposure)
                result.data["consistency_stage"] = stage
                result.seconds += stage["wall_s"]
                val_set = late_val
            if val_set is not None:
                result.validation = validate_autoencoder(result.model, val_set, cfg.features,
                                                         cfg.autoexposure)
        paths = ship_autoencoder(result, out_dir)
    if progress:
        print(json.dumps(result.summary(), indent=1, default=str))
        print(f"wrote {paths[0]} and {paths[1]}")
    return result, paths


__all__ = ["AEConfig", "AEConsistencyConfig", "AESequenceConfig", "consistency_stage",
           "resume_autoencoder", "NCAConfig", "TrainResult",
           "finetune_autoencoder_sequences", "run_training", "select_iterations",
           "ship_autoencoder", "ship_nca", "split", "train_autoencoder", "train_nca",
           "validate_autoencoder", "validate_autoencoder_sequences", "validate_nca"]
