"""``dbench run``'s work on one scene once the command line is parsed: the frames loaded over
the seeds, every runnable method run on them (a failing one named, not fatal), and every output
written into the run's folder: images, metrics, per-seed and per-frame tables, figures,
``run.json``, ``index.html``, ``run.log`` and ``report.md`` last (README.md, "Usage";
dbench/report/run_output.py stages the folder). The CLI (dbench/cli/run.py) parses, builds the
:class:`RunRequest` and prints the headline this returns.
"""
from __future__ import annotations

import json
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .inputs import (INPUT_FACTS, INPUT_WARNINGS, frames_text,  # noqa: F401 - the module's
                     input_metas, input_notes, method_failure)  # interface, as before


@dataclass
class RunRequest:
    """What ``dbench run`` was asked for, checked: samples per pixel, the resolution (a
    :class:`dbench.resolution.Res`), the first seed and the number of seeds, the sample
    transform and its λ, the reference's spp (None: the scene's default), the frames of a
    sequence and the bins of a transient video (None: the scene's), timed calls per method,
    whether to stay quiet, and the metric the rows are ranked by."""
    spp: int
    res: Any
    seed: int
    seeds: int
    transform: str | None
    lam: float
    ref_spp: int | None
    frames: int | None
    bins: int | None
    repeats: int
    quiet: bool
    rank_by: str
    notes: tuple[str, ...] = ()  # the command line's own, first in report.md's notes


def run_scene(out: Path, req: RunRequest, scene, instances, labels, runnable,
              skipped, device, cache, caught: list[str]):
    """Render, run every runnable method and write every output into folder ``out``; the
    (metrics table, failed methods, the headline's lines for the terminal). ``caught``: the
    library warnings so far (dbench/run/capture.py), written to ``run.log`` and counted in the
    report, which is written last so that the count covers every other output."""
    from . import harness, identity
    from .. import registry
    from ..report import run_report as report
    from ..report.headline import nondeterminism_text
    from ..report.formats import counted, markdown_text, write_csv
    from .machine import machine_info
    from .inputs import load_seeds
    from .harness import cell_record
    from ..device import device_name
    from ..io import write_exr, write_json, write_text

    import pandas as pd

    needs = set().union(*(registry.wants(instances[n], scene.provides) for n in runnable)) | {
        "reference"} | ({"emitter"} & set(scene.provides))
    frames = load_seeds(scene, req.seed, req.seeds, spp=req.spp, res=req.res, needs=needs,
                        transform=req.transform, lam=req.lam, ref_spp=req.ref_spp,
                        cache=cache, progress=not req.quiet, frames=req.frames,
                        bins=req.bins)
    frame = frames[0]
    is_sequence = frame.kind == "sequence"

    rows, per_seed, outputs, apart = [], [], [], []
    failed: dict[str, str] = {}
    for n in runnable:
        if not req.quiet:
            print(f"running {labels[n]} ...", flush=True)
        try:
            if is_sequence:
                res = harness.run_sequence_cell(instances[n], frames, device=device)
            else:
                res = harness.run_cell(instances[n], frames, repeats=req.repeats, device=device)
        except (Exception, SystemExit) as exc:  # noqa: BLE001 - a method's failure is its row
            # one method's error (or a plugin's sys.exit) never ends the run nor lends the
            # process its exit code: it is named here and in the report (exit code 4)
            failed[labels[n]] = method_failure(exc)
            print(f"error: {labels[n]} failed: {failed[labels[n]]}", file=sys.stderr)
            continue
        if res.skipped:
            skipped[n] = res.skipped
            continue
        record = cell_record(res, frames, registry.wants(instances[n], scene.provides))
        if res.nondeterministic:  # said now, where the user looks, and in the report's notes
            apart.append(nondeterminism_text(labels[n], res.nondeterministic))
            print(f"warning: {apart[-1]}", file=sys.stderr)
        rows.append({"scene": scene.name, "method": labels[n], "base_method": n,
                     "spp": req.spp, "res": req.res.key, **record,
                     "params": json.dumps(res.params, sort_keys=True, default=str)})
        per_seed += [{"scene": scene.name, "method": labels[n], "spp": req.spp, **r}
                     for r in res.per_seed]
        outputs.append((labels[n], res.sequence if is_sequence else res.output))
        write_exr(out / "images" / f"{identity.file_stem(labels[n])}.exr", {"color": res.output})
    last = frame[len(frame) - 1] if is_sequence else frame
    write_exr(out / "images" / "reference.exr", {"color": last.reference})

    table = pd.DataFrame(rows)
    csv_table = table.drop(columns=[c for c in ("seeds", "times_s", "per_seed", "settings",
                                                "nondeterministic") if c in table.columns])
    if failed:  # each failed method is a row of its own, with its error and no figures
        base = {lab: n for n, lab in labels.items()}
        csv_table = pd.concat([csv_table.assign(status="ok"), pd.DataFrame(
            [{"scene": scene.name, "method": label, "base_method": base.get(label, label),
              "spp": req.spp, "res": req.res.key, "status": "error", "error": why}
             for label, why in failed.items()])],
            ignore_index=True)
    write_csv(out / "metrics.csv", csv_table)
    write_csv(out / "metrics_per_seed.csv", pd.DataFrame(per_seed))
    if is_sequence:
        from ..report.sequence_figures import plot_errors, strip
        runs = dict(outputs)
        title = f"{scene.name}, {req.spp} spp, {req.res.text} px, {counted(len(frame), 'frame')}"
        plot_errors(runs, out / "error_per_frame.png", title=title,
                    events=frame.meta.get("events"))
        strip(frame, runs, out / "comparison.png", title=title)
        for n, run in runs.items():
            write_csv(out / f"per_frame_{identity.file_stem(n)}.csv", pd.DataFrame(run.per_frame))
    elif frame.kind == "transient":
        from ..report.transient_figures import write_figures
        write_figures(out, frame, dict(outputs), title=f"{scene.name}, {req.spp} spp")
    else:
        report.comparison_grid(out / "comparison.png", outputs, frame.reference, ev=scene.ev,
                               title=f"{scene.name}, {req.spp} spp, {req.res.text} px")
    info = machine_info()
    first = frame[0] if is_sequence else frame  # a folder's input facts live on its frames
    seeds = [req.seed + k for k in range(req.seeds)]
    from_files = first.meta.get("source") == "folder"
    settings = {"scene": scene.name, "kind": scene.kind,
                **({"scene parameters": ", ".join(f"{k}={v}" for k, v in
                                                  frame.meta["scene_params"].items())}
                   if frame.meta.get("scene_params") else {}),
                # what a scene file's render kept and changed (integrator, depth, filter)
                **frame.meta.get("scene_file_settings", {}),
                **folder_settings(first.meta),
                "spp": req.spp, "res": req.res.key,
                # a folder holds one noisy render per spp, made by whoever rendered it
                "seeds": ("one render per spp, from the files" if from_files
                          else ", ".join(map(str, seeds))),
                "ref_spp": frame.meta.get("ref_spp") or "unknown",
                **({} if from_files else {"reference seed": frame.meta.get("ref_seed")}),
                "reference RMSE (estimated)": ref_rmse_text(
                    judged_ref_rmse(frame) if is_sequence else frame.meta.get("ref_rmse"),
                    first.meta.get("ref_noise_source")),
                "repeats": (sequence_window(len(frame)) if is_sequence else req.repeats),
                "transform": transform_text(getattr(frame, "stats", None)),
                **({"tone-map EV": f"{first.meta['ev']:g} stops (the LDR metrics' exposure, "
                   f"{'dataset.json' if from_files else 'the scene'})"}
                   if first.meta.get("ev") else {}),
                "variant": frame.meta["versions"]["variant"],
                "device": device if device == "cpu" else f"{device} ({device_name(device)})",
                "render_s": frame.meta.get("render_s"),
                "cache hits": summarise_parts(frame.meta["cache_hits"]) or "none",
                "rendered": summarise_parts(frame.meta["rendered"]) or "nothing",
                "method parameters": "; ".join(f"{r['method']}: {r['params']}" for r in rows),
                # where each method ran and on what: CPU and GPU times are never compared unnamed
                "method devices": "; ".join(
                    f"{r['method']}: {r['device_name'] if r['device'] != 'cpu' else 'cpu'} "
                    f"({r['backend']}"
                    + (f", copies {r['transfer_s'] * 1e3:.2f} ms timed apart"
                       if r.get("transfer_s") else "") + ")" for r in rows)}
    metas, whole = input_metas(frame)
    # a plugin's label is any name: escaped as report.md escapes names
    notes = list(req.notes) + input_notes(metas, settings, whole) + [
        markdown_text(a) for a in apart]
    resolved = {r["method"]: r["settings"] for r in rows if r.get("settings")}
    if resolved:
        # what the methods resolved from "auto"/None defaults on this frame (first seed)
        settings["resolved settings"] = "; ".join(
            f"{m}: {json.dumps(v, sort_keys=True, default=str)}" for m, v in resolved.items())
    write_json(out / "run.json", {"settings": settings, "machine": info, "skipped": skipped,
                                  "failed": failed})
    write_run_page(out, scene, frame, outputs, table, settings, info, skipped, req, failed)
    from .capture import log_text
    write_text(out / "run.log", log_text(caught))
    write_text(out / "report.md", report.run_report_md(table, settings, info, skipped,
                                                       notes=notes, rank_by=req.rank_by,
                                                       failed=failed,
                                                       library_warnings=len(caught)))
    return table, failed, report.run_summary(table, settings, req.rank_by, failed)


def transform_text(stats) -> str:
    """The settings' transform: its name, with λ only where the transform takes one (the
    identity takes none, docs/methods/statistical.md §3); "n/a" without statistics."""
    if stats is None:
        return "n/a"
    return stats.transform if stats.transform == "identity" else (
        f"{stats.transform} (λ = {stats.lam})")


def ref_rmse_text(value, source: str | None = None):
    """The reference's estimated RMSE, or "unknown" where nothing gives its noise (a folder's
    external reference without a variance image or statistics): never a made-up 0. ``source``
    (dbench/datasets/folders/reference.py) says where the estimate came from, or why none."""
    import math
    if value is None or (isinstance(value, float) and math.isnan(value)):
        if source and source.startswith("unknown"):  # the source says so itself
            return source
        return f"unknown ({source or 'no variance or statistics of the reference were given'})"
    return f"{value} ({source})" if source else value


def folder_settings(meta: dict) -> dict[str, str]:
    """{"folder": its path} for the frame ``meta`` of a folder of renders (docs/formats.md),
    else {}: a folder's view is named like a catalogue scene ("cornell"), so the report says
    which files it scored."""
    if meta.get("source") != "folder":
        return {}
    return {"folder": str(meta.get("path", "?"))}


def write_run_page(out: Path, scene, frame, outputs, table, settings, info, skipped,
                    req: RunRequest, failed: dict[str, str] | None = None) -> None:
    """``index.html``: the run's interactive viewer and tables (dbench.report.html)."""
    from ..report import html, run_report as report, verdicts

    kind = frame.kind
    columns = (("rmse", "rmse_surface", "relmse", "ssim", "t_rmse", "tpsnr", "cvvdp", "time_s")
               if kind == "sequence" else (*verdicts.HEADLINE[:-1], "psnr", "time_s"))
    plots = {"sequence": [("error per frame", "error_per_frame.png"),
                          ("frames", "comparison.png")],
             "transient": [("streak image", "streak.png"), ("RMSE per bin", "rmse_per_bin.png"),
                           ("bins", "bins.png")]}.get(kind, [("comparison", "comparison.png")])
    title = f"{scene.name}, {req.spp} spp, {req.res.text} px"
    html.run_page(out, title=title, frame=frame, outputs=outputs,
                  table=report._run_frame(table, settings), columns=columns,
                  settings=settings, machine=info, skipped=skipped, ev=scene.ev,
                  plots=[(t, f) for t, f in plots if (out / f).exists()], rank_by=req.rank_by,
                  failed=failed)


def summarise_parts(parts: Sequence[str]) -> str:
    """``frame0, frame1, reference0`` → ``frame ×2, reference ×1`` (sequence renders are cached
    per frame); names without a frame number are listed as they are."""
    import re
    from collections import Counter

    counts = Counter(re.sub(r"\d+$", "", p) if re.search(r"\d+$", p) else p for p in parts)
    numbered = {re.sub(r"\d+$", "", p) for p in parts if re.search(r"\d+$", p)}
    return ", ".join(f"{k} ×{v}" if k in numbered else k for k, v in counts.items())


def judged_ref_rmse(seq) -> float | None:
    """A sequence's reference RMSE as its cells give it (``ref_rmse`` in metrics.csv): the mean,
    over the frames the metrics average (those after the warm-up, :func:`sequence_window`), of
    each frame's sqrt(mean(reference_var)); None where a frame's is unknown."""
    from .sequence_run import after_warmup

    judged = after_warmup([seq[k].meta.get("ref_rmse") for k in range(len(seq))])
    if not judged or any(v is None or v != v for v in judged):
        return None
    return float(np.mean(judged))


def sequence_window(n_frames: int) -> str:
    from ..report.formats import counted
    from .sequence_run import WARMUP

    if n_frames > WARMUP:
        return f"1 per frame; metrics and time over frames {WARMUP}-{n_frames - 1} of {n_frames}"
    return (f"1 per frame; metrics and time over all {counted(n_frames, 'frame')} (no more "
            f"frames than "
            f"the {WARMUP}-frame warm-up; frames 0-1 first run once untimed, then a reset)")


__all__ = ["INPUT_FACTS", "INPUT_WARNINGS", "RunRequest", "input_notes", "judged_ref_rmse",
           "method_failure", "ref_rmse_text", "run_scene", "sequence_window", "summarise_parts",
           "write_run_page"]
