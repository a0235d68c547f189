"""Regenerate ``results/learned.md``: quality of the learned denoisers against ``noisy``,
``jbf`` and ``oidn`` on the steady evaluation catalogue, and a same-run speed benchmark.

    DBENCH_CACHE=... python -m dbench.learn.evaluate [--res 128] [--spp 1,2,4] [--ref-spp 1024]
                                                     [--repeats 5] [--out results/learned.md]

Quality: every catalogue scene (cornell, mirrors, caustic, textured, fireflies) at each spp,
rendered (or read from the cache) by :func:`dbench.datasets.load`, metrics from
:mod:`dbench.metrics` (RMSE, relMSE ε = 1e-2, SSIM on the tone-mapped image). Methods that are
not registered (e.g. ``jbf`` before it exists) are left out and named in the report.

Speed: :func:`dbench.synthetic.base_frame` (the frame ``dbench bench`` uses) at 1280x720;
``nca`` (trained default steps), ``autoencoder`` and ``oidn`` timed in the same process,
interleaved round by round (one warm-up each), median of ``repeats``; the load average is printed
with the figures because the machine is shared.

Text between ``<!-- notes -->`` and ``<!-- /notes -->`` in an existing report is kept.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from pathlib import Path
from typing import Any, Sequence

from ..run import fpenv

EVAL_SCENES = ("cornell", "mirrors", "caustic", "textured", "fireflies")
METHODS = ("noisy", "jbf", "oidn", "nca", "autoencoder")
METRICS = ("rmse", "relmse", "ssim")
NOTES_OPEN, NOTES_CLOSE = "<!-- notes -->", "<!-- /notes -->"


def quality(scenes: Sequence[str] = EVAL_SCENES, spps: Sequence[int] = (1, 2, 4),
            res: int = 128, ref_spp: int = 1024, methods: Sequence[str] = METHODS,
            cache=None, seed: int = 0) -> tuple[list[dict[str, Any]], list[str]]:
    """Rows {scene, spp, method, rmse, relmse, ssim, time_s}; and the methods left out."""
    from .. import datasets, metrics
    from .. import registry

    present = [m for m in methods if m in registry.available()]
    missing = [m for m in methods if m not in present]
    rows = []
    for scene in scenes:
        for spp in spps:
            frame = datasets.load(scene, spp=spp, res=res, seed=seed, ref_spp=ref_spp,
                                  needs={"color", "albedo", "normal", "depth", "reference",
                                         "emitter"},
                                  cache=cache, progress=False)
            for name in present:
                m = registry.get(name)
                m.reset()
                t0 = time.perf_counter()
                out = fpenv.denoise(m, frame)
                dt = time.perf_counter() - t0
                vals = metrics.compute_all(out, frame.reference, names=list(METRICS),
                                           ev=frame.meta.get("ev", 0.0))
                rows.append({"scene": scene, "spp": spp, "method": name, **vals,
                             "time_s": dt})
    return rows, missing


SEQ_SCENES = ("orbit", "flicker", "mirror-pan")


def sequence_quality(scenes: Sequence[str] = SEQ_SCENES, spps: Sequence[int] = (1, 4),
                     res: int = 128, frames: int = 24, ref_spp: int = 256, warmup: int = 8,
                     cache=None, seed: int = 0) -> list[dict[str, Any]]:
    """The autoencoder on the catalogue's animated sequences, its hidden state reset every
    frame and carried from frame to frame (what the recurrence adds), against ``noisy`` and
    ``accumulate``: rows {scene, spp, method, rmse}, RMSE averaged over the frames after
    ``warmup`` (as the sequence sweep does)."""
    import numpy as np

    from .. import datasets
    from .. import registry
    from ..methods.autoencoder import autoencoder_denoise
    from ..metrics import rmse

    rows = []
    for scene in scenes:
        for spp in spps:
            seq = list(datasets.load(scene, spp=spp, res=res, frames=frames, ref_spp=ref_spp,
                                     seed=seed, cache=cache, progress=False))
            errs: dict[str, list[float]] = {"noisy": [], "accumulate": [],
                                            "autoencoder (state reset)": [],
                                            "autoencoder (state carried)": []}
            acc = registry.get("accumulate")
            acc.reset()
            hidden = None
            for i, f in enumerate(seq):
                outs = {"noisy": f.color, "accumulate": fpenv.denoise(acc, f)}
                # the ONNX session keeps the caller's floating-point environment itself
                # (methods/ort_session.py), so these direct calls need no guard
                outs["autoencoder (state reset)"], _ = autoencoder_denoise(
                    f.color, f.albedo, f.normal, f.depth)
                outs["autoencoder (state carried)"], hidden = autoencoder_denoise(
                    f.color, f.albedo, f.normal, f.depth, hidden=hidden)
                if i >= warmup:
                    for k, v in outs.items():
                        errs[k].append(rmse(v, f.reference))
            rows += [{"scene": scene, "spp": spp, "method": k, "rmse": float(np.mean(v))}
                     for k, v in errs.items()]
    return rows


def _sequence_table(rows: list[dict]) -> str:
    methods = list(dict.fromkeys(r["method"] for r in rows))
    keys = list(dict.fromkeys((r["scene"], r["spp"]) for r in rows))
    lines = ["| scene | spp | " + " | ".join(methods) + " |",
             "|---|---:|" + "---:|" * len(methods)]
    for scene, spp in keys:
        vals = {r["method"]: r["rmse"] for r in rows if (r["scene"], r["spp"]) == (scene, spp)}
        best = min(vals.values())
        lines.append(f"| {scene} | {spp} | " + " | ".join(
            f"**{vals[m]:.4f}**" if vals[m] == best else f"{vals[m]:.4f}" for m in methods)
            + " |")
    return "\n".join(lines)


def speed(height: int = 720, width: int = 1280, repeats: int = 5,
          methods: Sequence[str] = ("nca", "autoencoder", "oidn")) -> dict[str, Any]:
    """Median seconds per method on one synthetic frame, measured interleaved in one run."""
    from .. import registry
    from ..run.machine import machine_info
    from ..synthetic import base_frame

    frame = base_frame(height, width)
    insts = {m: registry.get(m) for m in methods}
    load0 = os.getloadavg()
    for m in insts.values():  # warm-up: session creation, JIT, thread pools
        m.reset()
        fpenv.denoise(m, frame)
    times: dict[str, list[float]] = {m: [] for m in insts}
    for _ in range(repeats):
        for name, m in insts.items():
            m.reset()
            t0 = time.perf_counter()
            fpenv.denoise(m, frame)
            times[name].append(time.perf_counter() - t0)
    info = machine_info()
    out = {"height": height, "width": width, "repeats": repeats,
           "median_s": {m: statistics.median(t) for m, t in times.items()},
           "min_s": {m: min(t) for m, t in times.items()}, "all_s": times,
           "loadavg_before": load0, "loadavg_after": os.getloadavg(),
           "cpu": info["cpu"], "cores": info["cores"],
           "when": time.strftime("%Y-%m-%d %H:%M:%S")}
    if "nca" in insts:
        from ..methods.nca import default_iterations
        out["nca_iterations"] = default_iterations()
    return out


def _table(rows: list[dict], spp: int, metric: str, methods: list[str], fmt: str) -> str:
    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    lines = ["| scene | " + " | ".join(methods) + " |",
             "|---|" + "---:|" * len(methods)]
    from ..metrics import higher_is_better

    better = "max" if higher_is_better(metric) else "min"
    for s in scenes:
        vals = {r["method"]: r[metric] for r in rows if r["scene"] == s and r["spp"] == spp}
        best = (max if better == "max" else min)(vals.values())
        cells = []
        for m in methods:
            v = vals.get(m, float("nan"))
            txt = format(v, fmt)
            cells.append(f"**{txt}**" if v == best else txt)
        lines.append(f"| {s} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _value(rows, scene, spp, method, metric="rmse") -> float:
    for r in rows:
        if r["scene"] == scene and r["spp"] == spp and r["method"] == method:
            return r[metric]
    return float("nan")


def checks(rows: list[dict], spps: Sequence[int]) -> list[str]:
    """The issue's quality checks, evaluated on ``rows`` (RMSE)."""
    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    methods = set(r["method"] for r in rows)
    lines = []
    for m in ("nca", "autoencoder"):
        if m not in methods or 4 not in spps:
            continue
        lose = [s for s in scenes if not _value(rows, s, 4, m) < _value(rows, s, 4, "noisy")]
        lines.append(f"- `{m}` beats `noisy` in RMSE at 4 spp on "
                     f"{len(scenes) - len(lose)}/{len(scenes)} scenes"
                     + (f" (not on: {', '.join(lose)})" if lose else "") + ".")
    if "autoencoder" in methods and "jbf" in methods:
        for spp in spps:
            wins = [s for s in scenes if _value(rows, s, spp, "autoencoder")
                    < _value(rows, s, spp, "jbf")]
            lines.append(f"- `autoencoder` beats `jbf` in RMSE at {spp} spp on {len(wins)}/"
                         f"{len(scenes)} scenes ({', '.join(wins) or 'none'}).")
    elif "jbf" not in methods:
        lines.append("- `jbf` was not registered when this ran: its comparison is missing.")
    if "oidn" in methods:
        for m in ("nca", "autoencoder"):
            if m not in methods:
                continue
            for spp in spps:
                lose = [s for s in scenes if _value(rows, s, spp, m)
                        > _value(rows, s, spp, "oidn")]
                lines.append(f"- `{m}` vs `oidn` at {spp} spp: worse RMSE on {len(lose)}/"
                             f"{len(scenes)} scenes ({', '.join(lose) or 'none'}).")
    return lines


def _training_section() -> str:
    from ..methods.autoencoder import SHIPPED_JSON as AE_JSON
    from ..methods.nca import SHIPPED_JSON as NCA_JSON

    lines = ["| | nca | autoencoder |", "|---|---|---|"]
    infos = {}
    for name, path in (("nca", NCA_JSON), ("autoencoder", AE_JSON)):
        infos[name] = json.loads(Path(path).read_text(encoding="utf-8")) if Path(path).exists() else {}

    def get(info, *keys, default="-"):
        for k in keys:
            if not isinstance(info, dict) or k not in info:
                return default
            info = info[k]
        return info

    def fmt(v):
        return f"{v:.5f}" if isinstance(v, float) else str(v)

    rows = [
        ("trained on", lambda i: f"{get(i, 'trained_on')} ({get(i, 'machine', 'cpu')}, "
                                 f"{get(i, 'machine', 'torch_threads')} torch threads)"),
        ("wall time", lambda i: f"{get(i, 'losses', 'wall_s')} s"),
        ("optimiser steps", lambda i: get(i, "losses", "steps_done")),
        ("batch x crop", lambda i: f"{get(i, 'training_config', 'batch')} x "
                                   f"{get(i, 'training_config', 'crop')}²"),
        ("trainable parameters", lambda i: get(i, "parameters")),
        ("final training loss (mean of last 100 steps)",
         lambda i: fmt(get(i, "losses", "final_train_loss"))),
        ("loss parts", lambda i: ", ".join(f"{k} {v:.5f}" for k, v in
                                           get(i, "losses", "final_train_parts",
                                               default={}).items())),
        ("held-out loss (model / noisy input)",
         lambda i: f"{fmt(get(i, 'losses', 'validation', 'loss'))} / "
                   f"{fmt(get(i, 'losses', 'validation', 'noisy_input_loss'))}"),
        ("training scenes (held out)",
         lambda i: f"{len(get(i, 'data', 'scenes', default=[]))} "
                   f"({', '.join(get(i, 'losses', 'validation', 'scenes', default=[]))})"),
        ("data hash (training part)", lambda i: f"`{str(get(i, 'data', 'hash'))[:16]}…`"),
        ("sequence stage (steps, wall time)",
         lambda i: "-" if get(i, "data", "sequence_stage") == "-" else
         f"{get(i, 'data', 'sequence_stage', 'steps_done')} steps, "
         f"{get(i, 'data', 'sequence_stage', 'wall_s')} s, "
         f"{len(get(i, 'data', 'sequence_stage', 'data', 'scenes', default=[]))} sequences"),
        ("held-out sequences: loss with state carried / reset",
         lambda i: "-" if get(i, "data", "sequence_stage") == "-" else
         f"{fmt(get(i, 'data', 'sequence_stage', 'validation', 'loss_state_carried'))} / "
         f"{fmt(get(i, 'data', 'sequence_stage', 'validation', 'loss_state_reset'))}"),
        ("consistency stage (steps, wall time, relative term)",
         lambda i: "-" if get(i, "data", "consistency_stage") == "-" else
         f"{get(i, 'data', 'consistency_stage', 'steps_done')} steps, "
         f"{get(i, 'data', 'consistency_stage', 'wall_s')} s, "
         f"{get(i, 'data', 'consistency_stage', 'config', 'relative_weight')} x "
         f"{get(i, 'data', 'consistency_stage', 'config', 'relative_metric')} ratio, "
         f"ε {get(i, 'data', 'consistency_stage', 'config', 'relative_eps')}, "
         f"on {get(i, 'data', 'consistency_stage', 'machine', 'cpu')}"),
        ("held-out sequences after it: carried / reset",
         lambda i: "-" if get(i, "data", "consistency_stage") == "-" else
         f"{fmt(get(i, 'data', 'consistency_stage', 'validation', 'loss_state_carried'))} / "
         f"{fmt(get(i, 'data', 'consistency_stage', 'validation', 'loss_state_reset'))}"),
    ]
    for label, f in rows:
        lines.append(f"| {label} | {f(infos['nca'])} | {f(infos['autoencoder'])} |")
    return "\n".join(lines)


def render_markdown(rows: list[dict], missing: list[str], spd: dict | None,
                    settings: dict, notes: str = "", seq_rows: list[dict] | None = None
                    ) -> str:
    methods = [m for m in METHODS if any(r["method"] == m for r in rows)]
    spps = sorted(set(r["spp"] for r in rows))
    out = ["# Learned denoisers: `nca` (TNND) and `autoencoder` (recurrent denoising autoencoder)",
           "",
           "Generated by `python -m dbench.learn.evaluate` "
           f"({settings.get('when', '')}); text in the notes block is written by hand and kept "
           "when the file is regenerated.", "",
           "## Settings", "",
           f"- Scenes: the steady evaluation catalogue ({', '.join(EVAL_SCENES)}), "
           f"{settings['res']}x{settings['res']} px, reference {settings['ref_spp']} spp, "
           f"noisy seed {settings.get('seed', 0)}; methods with default parameters.",
           "- Metrics: RMSE and relMSE (ε = 1e-2) on linear HDR values; SSIM on the tone-mapped "
           "sRGB image (the scene's EV). Bold: best in the row.",
           f"- Left out (not registered when this ran): {', '.join(missing) or 'none'}.", "",
           "## Training (from the JSON files shipped beside the ONNX weights)", "",
           _training_section(), ""]
    out += ["## Checks", ""] + checks(rows, spps) + [""]
    for metric, fmt in (("rmse", ".4f"), ("relmse", ".4f"), ("ssim", ".3f")):
        for spp in spps:
            out += [f"### {metric.upper() if metric != 'relmse' else 'relMSE'}, {spp} spp", "",
                    _table(rows, spp, metric, methods, fmt), ""]
    if seq_rows:
        out += ["## Sequences: what the recurrence adds", "",
                f"The catalogue's animated sequences, {settings['res']}x{settings['res']} px, "
                f"{settings.get('frames', 24)} frames, reference {settings.get('seq_ref_spp', 256)}"
                f" spp; RMSE averaged over frames {settings.get('warmup', 8)}.."
                f"{settings.get('frames', 24) - 1} (as in the sequence sweep). The same shipped "
                "autoencoder with its hidden state reset every frame and carried from frame to "
                "frame; `accumulate` (the temporal baseline) for scale.", "",
                _sequence_table(seq_rows), ""]
    if spd:
        med = spd["median_s"]
        out += ["## Speed (1280x720, same run)", "",
                f"{spd['width']}x{spd['height']}, synthetic frame "
                "(`dbench.synthetic.base_frame`), one warm-up then the median of "
                f"{spd['repeats']} interleaved rounds; {spd['cpu']}, {spd['cores']} cores shared "
                f"with other jobs (load average {spd['loadavg_before'][0]:.2f} before, "
                f"{spd['loadavg_after'][0]:.2f} after); {spd['when']}.", "",
                "| method | median ms | min ms | vs oidn |", "|---|---:|---:|---:|"]
        for m, t in med.items():
            label = f"nca ({spd.get('nca_iterations')} steps)" if m == "nca" else m
            ratio = t / med["oidn"] if "oidn" in med else float("nan")
            out.append(f"| {label} | {t * 1e3:.0f} | {spd['min_s'][m] * 1e3:.0f} | "
                       f"{ratio:.2f}x |")
        out.append("")
    out += ["## Notes", "", NOTES_OPEN, notes.strip("\n"), NOTES_CLOSE, ""]
    return "\n".join(out)


def _existing_notes(path: Path) -> str:
    if not path.exists():
        return ""
    text = path.read_text(encoding="utf-8")
    if NOTES_OPEN in text and NOTES_CLOSE in text:
        return text.split(NOTES_OPEN, 1)[1].split(NOTES_CLOSE, 1)[0]
    return ""


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--res", type=int, default=128)
    p.add_argument("--spp", default="1,2,4")
    p.add_argument("--ref-spp", type=int, default=1024)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--no-speed", action="store_true")
    p.add_argument("--no-sequences", action="store_true")
    p.add_argument("--out", default="results/learned.md")
    args = p.parse_args(argv)
    spps = [int(s) for s in args.spp.split(",")]
    rows, missing = quality(spps=spps, res=args.res, ref_spp=args.ref_spp)
    seq_rows = None if args.no_sequences else sequence_quality(res=args.res)
    spd = None if args.no_speed else speed(repeats=args.repeats)
    out = Path(args.out)
    settings = {"res": args.res, "ref_spp": args.ref_spp, "seed": 0, "frames": 24,
                "seq_ref_spp": 256, "warmup": 8, "when": time.strftime("%Y-%m-%d %H:%M")}
    from ..io import write_json, write_text

    write_text(out, render_markdown(rows, missing, spd, settings, _existing_notes(out),
                                    seq_rows))
    write_json(out.with_suffix(".json"), {"settings": settings, "rows": rows,
                                          "missing": missing, "speed": spd,
                                          "sequence_rows": seq_rows})
    print(f"wrote {out} and {out.with_suffix('.json')}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
