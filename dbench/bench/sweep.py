"""The benchmark grid: methods × scenes × spp, resumable, on a local process pool or Ray.

Each cell's result is its own JSON file, written atomically:
``<out>/cells/<scene>/<spp:05d>spp/<method>.json`` with ``status`` ``ok``, ``skipped`` (with the
reason) or ``error`` (with the message). A sweep run again reads the finished cells and computes
only the missing ones, so a killed sweep loses at most the cells in flight.

Steady and transient cells time ``repeats`` calls after a warm-up; a sequence cell runs the
method once over the frames in order and reports the means after the warm-up frames
(:func:`dbench.bench.harness.run_sequence_cell`).

Work is grouped by (scene, spp): one group loads the frame once (renders are cached and shared)
and runs every method on it. References are rendered once per scene before the groups are
dispatched, so parallel workers never render the same reference twice.
"""
from __future__ import annotations

import json
import traceback
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Sequence

from .. import io

DEFAULT_SPP = (4, 16, 64, 256, 1024)
#: Settings every cell of one sweep folder shares; methods, scenes and spp may be extended.
SETTINGS = ("res", "ref_spp", "seed", "repeats", "transform", "lam", "metrics", "frames", "bins")


@dataclass
class SweepConfig:
    """Everything that defines a sweep (stored as ``<out>/sweep.json``)."""

    methods: list[str]
    scenes: list[str]
    spp: list[int]
    res: int = 128
    ref_spp: int | None = None
    seed: int = 0
    repeats: int = 5
    #: None: each kind's default (Box-Cox for steady scenes, identity for transient ones).
    transform: str | None = None
    lam: float = 0.5
    #: sequence scenes: frames from the start (None: all); transient scenes: time bins (None:
    #: the scene's default).
    frames: int | None = None
    bins: int | None = None
    params: dict[str, dict[str, Any]] = field(default_factory=dict)
    cache: str | None = None
    metrics: list[str] = field(default_factory=lambda: ["rmse", "relmse", "smape", "psnr",
                                                        "ssim", "flip"])


def cell_path(out: Path, scene: str, spp: int, method: str) -> Path:
    return out / "cells" / scene / f"{spp:05d}spp" / f"{method}.json"


def read_cell(path: Path) -> dict | None:
    try:
        return io.read_json(path)
    except (OSError, ValueError):
        return None


def resolve_names(methods: str | Sequence[str], scenes: str | Sequence[str]
                  ) -> tuple[list[str], list[str]]:
    """``all`` or comma lists → validated names (UnknownNameError lists the valid ones)."""
    from .. import methods as registry
    from ..datasets import scenes as catalogue

    def split(v):
        return [s.strip() for s in v.split(",") if s.strip()] if isinstance(v, str) else list(v)

    m = registry.available() if methods == "all" else split(methods)
    s = catalogue.available() if scenes == "all" else split(scenes)
    for name in m:
        registry.method_class(name)
    for name in s:
        catalogue.get(name)
    if "noisy" not in m:
        m = ["noisy"] + m
    return m, s


def plan(config: SweepConfig, out: Path
         ) -> tuple[list[tuple[str, int, list[str]]], int, int]:
    """Groups still to compute: (scene, spp, [methods]); newly skipped cells are written here.

    Returns the groups, the number of cells finished (or skipped) by an earlier run, and the
    number of cells skipped now because the method does not apply to the scene.
    """
    from .. import methods as registry
    from ..datasets import scenes as catalogue

    groups, done, skipped = [], 0, 0
    for scene_name in config.scenes:
        scene = catalogue.get(scene_name)
        for spp in config.spp:
            todo = []
            for m in config.methods:
                path = cell_path(out, scene_name, spp, m)
                cell = read_cell(path)
                if cell is not None and cell.get("status") in ("ok", "skipped"):
                    done += 1
                    continue
                method = registry.get(m, **config.params.get(m, {}))
                ok, why = method.applies_to(scene.kind, set(scene.provides))
                if not ok:
                    io.write_json(path, {"status": "skipped", "reason": why, "scene": scene_name,
                                         "method": m, "spp": spp, "res": config.res})
                    skipped += 1
                    continue
                todo.append(m)
            if todo:
                groups.append((scene_name, spp, todo))
    return groups, done, skipped


def run_group(config: SweepConfig, out: str, scene_name: str, spp: int,
              method_names: list[str]) -> list[str]:
    """Load one frame and run the given methods on it, writing one cell file each."""
    from .. import datasets, methods as registry
    from .harness import run_cell, run_sequence_cell

    out_path = Path(out)
    cache = datasets.Cache(config.cache)
    needs = {"reference"}
    instances = {m: registry.get(m, **config.params.get(m, {})) for m in method_names}
    for inst in instances.values():
        needs |= set(inst.needs)
    frame = datasets.load(scene_name, spp=spp, res=config.res, needs=needs, seed=config.seed,
                          transform=config.transform, lam=config.lam, ref_spp=config.ref_spp,
                          cache=cache, progress=False, frames=config.frames, bins=config.bins)
    is_sequence = frame.kind == "sequence"
    render_s = frame.meta.get("render_s")
    if render_s is None:
        render_s = float("nan")
    written = []
    for m, inst in instances.items():
        base = {"scene": scene_name, "method": m, "spp": spp, "res": config.res,
                "params": inst.params, "render_s": render_s,
                "stats_s": frame.meta.get("stats_s") if "stats" in inst.needs else 0.0,
                "ref_spp": frame.meta.get("ref_spp")}
        try:
            if is_sequence:
                res = run_sequence_cell(inst, frame, metric_names=config.metrics)
            else:
                res = run_cell(inst, frame, metric_names=config.metrics, repeats=config.repeats)
            if res.skipped:
                cell = {**base, "status": "skipped", "reason": res.skipped}
            else:
                cell = {**base, "status": "ok", **res.metrics, "time_s": res.time_s,
                        "times_s": res.times_s, "n_nonfinite": res.n_nonfinite}
                if is_sequence:
                    cell.update(frames=len(frame), warmup=res.sequence.summary["warmup"])
        except Exception as exc:  # noqa: BLE001 - one failing method must not stop the sweep
            cell = {**base, "status": "error", "error": f"{type(exc).__name__}: {exc}",
                    "traceback": traceback.format_exc(limit=5)}
        io.write_json(cell_path(out_path, scene_name, spp, m), cell)
        written.append(m)
    return written


def _prerender_references(config: SweepConfig, scenes: Iterable[str]) -> None:
    from .. import datasets

    cache = datasets.Cache(config.cache)
    for s in scenes:
        datasets.load(s, spp=1, res=config.res, needs={"reference", "albedo"}, seed=config.seed,
                      ref_spp=config.ref_spp, cache=cache, frames=config.frames,
                      bins=config.bins)


def run_sweep(config: SweepConfig, out: str | Path, executor: str = "local", workers: int = 1,
              progress: bool = True) -> dict[str, int]:
    """Run (or resume) a sweep; returns counts of computed, already finished and failed cells."""
    from tqdm.auto import tqdm

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    config_file = out / "sweep.json"
    stored = read_cell(config_file)
    new = _config_dict(config)
    from .harness import machine_info
    if stored is not None:
        old = stored.get("config", {})
        differ = [k for k in SETTINGS if old.get(k) != new.get(k)]
        if differ:
            raise ValueError(f"{out} holds a sweep with other settings ({', '.join(differ)}); "
                             "use another --out or the same settings to resume or extend it")
        # Extending a sweep with more methods, scenes or spp keeps every finished cell.
        for key in ("methods", "scenes", "spp"):
            new[key] = old.get(key, []) + [v for v in new[key] if v not in old.get(key, [])]
        new["params"] = {**old.get("params", {}), **new["params"]}
        if new != old:
            io.write_json(config_file, {**stored, "config": new})
    else:
        io.write_json(config_file, {"config": new, "machine": machine_info()})

    groups, done, skipped = plan(config, out)
    if not groups:
        return {"computed": 0, "skipped": skipped, "finished_before": done,
                "errors": _count_errors(out)}
    _prerender_references(config, sorted({g[0] for g in groups}))
    n_cells = sum(len(g[2]) for g in groups)
    bar = tqdm(total=n_cells, desc="sweep", unit="cell", disable=not progress)
    if executor == "ray":
        import ray

        if not ray.is_initialized():
            ray.init(ignore_reinit_error=True, include_dashboard=False, log_to_driver=False)
        remote = ray.remote(run_group)
        pending = [remote.remote(config, str(out), *g) for g in groups]
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            bar.update(len(ray.get(ready[0])))
    elif workers > 1:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            futures = [pool.submit(run_group, config, str(out), *g) for g in groups]
            for f in as_completed(futures):
                bar.update(len(f.result()))
    else:
        for g in groups:
            bar.update(len(run_group(config, str(out), *g)))
    bar.close()
    return {"computed": n_cells, "skipped": skipped, "finished_before": done,
            "errors": _count_errors(out)}


def _count_errors(out: Path) -> int:
    return sum(1 for p in (out / "cells").rglob("*.json")
               if (read_cell(p) or {}).get("status") == "error")


def _config_dict(config: SweepConfig) -> dict:
    d = dict(config.__dict__)
    d.pop("cache", None)  # where renders are cached does not change results
    return json.loads(json.dumps(d, default=str))


def load_cells(out: str | Path) -> list[dict]:
    """Every cell file of a sweep folder, sorted by scene, spp, method."""
    cells = [c for p in sorted(Path(out).glob("cells/*/*/*.json")) if (c := read_cell(p))]
    return sorted(cells, key=lambda c: (c["scene"], c["spp"], c["method"]))
