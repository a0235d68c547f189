"""The benchmark grid: methods × scenes × spp, resumable, on a local process pool or Ray.

Each cell's result is its own JSON file, written atomically:
``<out>/cells/<scene>/<spp:05d>spp/<method>.json`` with ``status`` ``ok``, ``skipped`` (with the
reason) or ``error`` (with the message), and ``input_warnings`` where the cell's input doubts
itself (:func:`dbench.run.inputs.input_warnings`: a folder's reference or normals, NaN or ±Inf
samples, nothing to denoise), the lines ``dbench run`` prints, which the sweep's summary and
``dbench report`` say.
A sweep run again reads the finished cells and computes only the missing ones, so a killed
sweep loses at most the cells in flight.

Steady and transient cells time ``repeats`` calls after a warm-up; a sequence cell runs the
method once over the frames in order and reports the means after the warm-up frames
(:func:`dbench.run.harness.run_sequence_cell`).

Work is grouped by (scene, spp): one group loads the frame once (renders are cached and shared)
and runs every method on it. References are rendered once per scene, and refused when black,
before the sweep writes anything to its folder (:func:`dbench.run.sweep_names.render_references`),
so parallel workers never render the same reference twice.

``<scene>`` is the scene's label (:func:`scene_labels`): its name, unless another scene of the
sweep has that name (``a/cbox.xml`` and ``b/cbox.xml``); a scene's identity is its fingerprint,
never its name (README.md, the ``dbench sweep`` paragraph).
"""
from __future__ import annotations

import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

from .. import io
from ..data import check_count
from ..errors import DbenchInputError
from ..resolution import MAX_SIDE, Res, parse_res
from . import identity, sweep_history, sweep_lock, sweep_pool
from ..report.cells import (NUMERIC_KEYS, cell_problem, load_cells,  # noqa: F401 - the module's
                            load_cells_checked, read_cell)  # interface, as before
from .sweep_history import SETTINGS, stored_config  # noqa: F401 - the module's interface
from .inputs import MethodError, input_warnings, load_seeds, method_failure  # noqa: F401
from .sweep_names import (check_scenes, folder_ref_spp, kind_options, render_references,
                          scene_labels)
from .sweep_pool import worker_start as _worker_start  # noqa: F401 - the pool initializer
from ..device import device_name

DEFAULT_SPP = (4, 16, 64, 256, 1024)


@dataclass
class SweepConfig:
    """Everything that defines a sweep (stored as ``<out>/sweep.json``)."""

    methods: list[str]
    scenes: list[str]
    spp: list[int]
    #: image size: a side (square) or "WxH" (dbench.resolution; stored in its key form);
    #: None: each scene's default (dbench.datasets.default_res)
    res: int | str | None = 128
    ref_spp: int | None = None
    seed: int = 0
    #: independent noisy renders per cell (seeds ``seed`` … ``seed + seeds − 1``), all scored
    #: against one reference rendered with ``seed``.
    seeds: int = 1
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
    #: --no-cache: render everything afresh and write nothing to the cache
    no_cache: bool = False
    metrics: list[str] = field(default_factory=lambda: ["rmse", "relmse", "smape", "psnr",
                                                        "ssim", "flip"])
    #: recompute cells whose identity changed (otherwise such a sweep is refused)
    rerun: bool = False
    #: ``$parameters`` of scene files and declared parameters of catalogue scenes, for every
    #: scene (--scene-param NAME=VALUE) and for one (SCENE:NAME=VALUE: {scene: {name: value}})
    scene_params: dict[str, str] = field(default_factory=dict)
    scene_params_by_scene: dict[str, dict[str, str]] = field(default_factory=dict)
    #: where methods with a device path run ("cpu" or "cuda"; docs/gpu.md §3)
    device: str = "cpu"
    #: how the normals of the sweep's folders of renders are read (None: as each one says)
    normal_encoding: str | None = None
    #: what the run's entry in sweep.json notes for the report (what "all" left out)
    notes: list[str] = field(default_factory=list)

    def validate(self) -> None:
        """Every setting checked before anything is written or rendered (DbenchInputError)."""
        from ..device import resolve_device
        self.device = resolve_device(self.device)
        if self.res is not None:
            self.res = parse_res(self.res, "--res").key
        for name, value in (("--seeds", self.seeds), ("--repeats", self.repeats)):
            check_count(name, value)
        for value in self.spp:
            check_count("--spp", value)
        if not self.spp:
            raise DbenchInputError("--spp: expected a comma list of integers >= 1, got none")
        if self.ref_spp is not None:
            check_count("--ref-spp", self.ref_spp)
        for name, value in (("--frames", self.frames), ("--bins", self.bins)):
            if value is not None:
                check_count(name, value)
        from ..datasets.scenes.scoped import check_config

        check_config(self.scene_params, self.scene_params_by_scene, self.scenes, "--scenes")

    def params_of(self, name: str) -> dict[str, str]:
        """The ``--scene-param`` values of scene ``name`` (as written in ``scenes``): every
        scene's and its own (dbench.datasets.scenes.scoped)."""
        from ..datasets.scenes.scoped import values_for

        return values_for(self.scene_params, self.scene_params_by_scene, name)

    def scene(self, name: str):
        """The Scene of a catalogue name, scene file or folder (with its :meth:`params_of`; a
        folder's normals read as ``normal_encoding``)."""
        from ..datasets.scenes import catalogue, scoped

        scene = scoped.scene_of(name, self.scene_params, self.scene_params_by_scene)
        return scene if scene.renders else \
            catalogue.with_normal_encoding(scene, self.normal_encoding, name)

    def res_for(self, scene) -> Res:
        """The size ``scene`` is rendered at: ``res``, or the scene's default when None."""
        from .. import datasets

        return parse_res(self.res) if self.res is not None else datasets.default_res(scene)

    @property
    def seed_list(self) -> list[int]:
        return [self.seed + k for k in range(self.seeds)]

    def labels(self) -> dict[str, str]:
        """{method name: label} (``jbf`` or ``jbf[radius=3]``)."""
        return {m: identity.label(m, self.params.get(m)) for m in self.methods}


#: Largest image side a sweep or run accepts (a 4096² float64 statistics buffer is ~1.2 GB).
MAX_RES = MAX_SIDE


def cell_path(out: Path, scene: str, spp: int, label: str) -> Path:
    """The cell file of (scene label, spp, method label). A label of a scene whose name another
    scene of the sweep has (``b/cbox.xml``) makes a folder name of its own."""
    folder = scene if "/" not in scene else identity.file_stem(scene)
    return out / "cells" / folder / f"{spp:05d}spp" / f"{identity.file_stem(label)}.json"


def resolve_names(methods: str | Sequence[str], scenes: str | Sequence[str],
                  scene_params: dict[str, str] | None = None,
                  by_scene: dict[str, dict[str, str]] | None = None
                  ) -> tuple[list[str], list[str]]:
    """``all`` or comma lists → validated names (UnknownNameError lists the valid ones); each
    scene with ``scene_params`` and its own ``by_scene`` values (SweepConfig.params_of)."""
    from .. import registry
    from ..datasets.scenes import catalogue
    from ..datasets.scenes.scoped import scene_of

    def split(v):
        return [s.strip() for s in v.split(",") if s.strip()] if isinstance(v, str) else list(v)

    m = registry.available() if methods == "all" else [registry.canonical(n)
                                                          for n in split(methods)]
    s = catalogue.available() if scenes == "all" else split(scenes)
    for name in m:
        registry.method_class(name)
    for name in s:
        scene_of(name, scene_params or {}, by_scene or {})
    if "noisy" not in m:
        m = ["noisy"] + m
    return m, s


def resolved_ref_spp(config: SweepConfig, scene, spp: int) -> int | None:
    """The reference spp a cell will use (the kind's rule for a missing --ref-spp)."""
    from .. import datasets

    if not scene.renders:  # a folder of renders: its reference, whatever was asked
        return scene.info.ref_spp
    if scene.kind == "transient":
        from ..datasets.transient import load as transient
        return transient.reference_spp(spp, config.ref_spp)
    return int(config.ref_spp or datasets.reference_spp())


def cell_identity(config: SweepConfig, scene, spp: int, method: str, fingerprint: str,
                  label: str | None = None) -> dict[str, Any]:
    """Everything that changes a cell's numbers (module docstring of run/identity.py);
    ``label``: the scene's label when it is not its name (:func:`scene_labels`)."""
    from .. import datasets, registry

    # a folder's statistics are what they are (a --transform other than theirs is refused)
    transform, lam = (scene.info.stats_settings.get(spp) if not scene.renders else None) or (
        config.transform or datasets.default_transform(scene.kind), float(config.lam))
    return {"scene": label or scene.name, "scene_fingerprint": fingerprint, "kind": scene.kind,
            "res": config.res_for(scene).key, "spp": int(spp), "seeds": config.seed_list,
            "ref_spp": resolved_ref_spp(config, scene, spp), "ref_seed": config.seed,
            "transform": transform, "lam": lam, **kind_options(config, scene),
            "metrics": list(config.metrics), "method": method,
            "params": identity.resolved_params(method, config.params.get(method)),
            "method_version": identity.method_version(
                registry.method_class(method),
                config.device if registry.method_class(method).has_device_path() else "cpu"),
            "judge_version": identity.judge_version(),
            **datasets.feature_identity(scene, spp),
            # a GPU cell is another result than the CPU one (other arithmetic, other times);
            # CPU cells keep the identity they had before devices were recorded
            **({"device": config.device, "device_name": device_name(config.device)}
               if config.device != "cpu" and registry.method_class(method).has_device_path()
               else {})}


def plan(config: SweepConfig, out: Path
         ) -> tuple[list[tuple[str, int, list[str], dict[str, dict]]], int,
                    list[tuple[Path, dict]]]:
    """Groups still to compute: (scene, spp, [methods], {method: its cell's identity}). Writes
    nothing.

    Returns the groups, the number of cells finished (or skipped) by an earlier run with the
    same identity, and the cells skipped now because the method does not apply, as (path,
    cell) for :func:`run_sweep` to write once nothing refused the sweep.
    Raises DbenchInputError, before anything is rendered, when a finished cell under the same
    label was computed with another identity (changed defaults, code, reference spp...) and
    ``config.rerun`` is false.
    """
    from .. import datasets, registry

    labels = config.labels()
    groups, done, conflicts = [], 0, []
    pending_skips = []
    scene_label = scene_labels(config, out)
    planned = set()
    for scene_name in config.scenes:
        scene = config.scene(scene_name)
        if scene_label[scene_name] in planned:  # the same scene given twice
            continue
        planned.add(scene_label[scene_name])
        fingerprint = datasets.scene_fingerprint(scene, config.res_for(scene))
        for spp in config.spp:
            todo = {}
            for m in config.methods:
                path = cell_path(out, scene_label[scene_name], spp, labels[m])
                ident = cell_identity(config, scene, spp, m, fingerprint,
                                      scene_label[scene_name])
                key = identity.digest(ident)
                cell = read_cell(path)
                if cell is not None and not cell_problem(cell) and \
                        cell.get("status") in ("ok", "skipped"):
                    if cell.get("identity_hash") == key:
                        done += 1
                        continue
                    if not config.rerun:
                        diff = identity.differences(cell.get("identity") or {}, ident)
                        conflicts.append(f"{path.relative_to(out).as_posix()} "
                                         f"(differs in {', '.join(diff[:6]) or 'identity'})")
                        continue
                method = registry.get(m, **config.params.get(m, {}))
                ok, why = registry.applies(method, scene.kind, set(scene.provides))
                if not ok:
                    pending_skips.append((path, {
                        "status": "skipped", "reason": why, "scene": scene_label[scene_name],
                        "method": labels[m], "base_method": m, "spp": spp,
                        "res": config.res_for(scene).key,
                        "identity": ident, "identity_hash": key}))
                    continue
                registry.wants(method, scene.provides)  # a plugin's failure: before any render
                todo[m] = ident
            if todo:
                groups.append((scene_name, spp, list(todo), todo))
    if conflicts:
        raise DbenchInputError(
            f"{len(conflicts)} finished cell(s) under the same label were computed with other "
            f"settings or code: {'; '.join(conflicts[:3])}"
            + (f" and {len(conflicts) - 3} more" if len(conflicts) > 3 else "")
            + "; use --rerun to recompute them, or another --out")
    return groups, done, pending_skips


def run_group(config: SweepConfig, out: str, scene_name: str, spp: int,
              method_names: list[str], planned: dict[str, dict] | None = None,
              beside: int = 0) -> list[str]:
    """Load one frame per seed and run the given methods on them, writing one cell file each.
    ``planned``: each method's cell identity as :func:`plan` found it; a cell whose identity
    differs here (its code edited since, read by this worker) is an error cell, not scored
    (:func:`dbench.run.identity.changed_during_sweep`). ``beside``: how many other groups may
    run on this machine while these methods are timed, recorded as each cell's
    ``timed_beside`` (:func:`dbench.run.sweep_pool.execute`; not part of its identity)."""
    from .. import datasets, registry
    from .harness import cell_record, run_cell, run_sequence_cell

    out_path = Path(out)
    cache = datasets.Cache(config.cache, enabled=not config.no_cache)
    scene = config.scene(scene_name)
    res = config.res_for(scene)
    fingerprint = datasets.scene_fingerprint(scene, res)
    scene_label = scene_labels(config, out_path)[scene_name]
    needs = {"reference"} | ({"emitter"} & set(scene.provides))
    instances, unbuilt = {}, {}
    for m in method_names:  # a worker starts afresh: a plugin file removed since is not there
        try:
            instances[m] = registry.get(m, **config.params.get(m, {}))
        except (Exception, SystemExit) as exc:  # noqa: BLE001 - that method's cells only
            unbuilt[m] = _unbuilt(m, exc)
    for inst in instances.values():
        needs |= registry.wants(inst, scene.provides)
    # (an unbuilt method is filed under its name: its defaults, which a label reads, are unknown)
    labels = {m: identity.label(m, config.params.get(m)) if m in instances else m
              for m in method_names}
    frames = load_seeds(scene, config.seed, config.seeds, spp=spp, res=res,
                        needs=needs, transform=config.transform, lam=config.lam,
                        ref_spp=folder_ref_spp(config, scene), cache=cache, progress=False,
                        **kind_options(config, scene))
    # what the input says of itself, as `dbench run` prints it (first seed, as there):
    # every cell of the group records it, and the sweep's summary and report say it
    said = input_warnings(frames[0])
    written = []
    for m in method_names:
        inst = instances.get(m)
        # this process's hash of the code (a pool worker's own: sweep_pool.worker_start)
        # (an unbuilt method's cell keeps the identity the sweep planned for it)
        ident = ((planned or {}).get(m) or {"params": config.params.get(m, {})} if m in unbuilt
                 else cell_identity(config, scene, spp, m, fingerprint, scene_label))
        changed = unbuilt.get(m) or identity.changed_during_sweep(
            m, (planned or {}).get(m), ident)
        base = {"scene": scene_label, "method": labels[m], "base_method": m, "spp": spp,
                "res": res.key, "params": ident["params"], "identity": ident,
                "identity_hash": identity.digest(ident),
                **({"input_warnings": said} if said else {})}
        try:
            if changed:
                raise MethodError(changed)
            if frames[0].kind == "sequence":
                result = run_sequence_cell(inst, frames, metric_names=config.metrics,
                                           device=config.device)
            else:
                result = run_cell(inst, frames, metric_names=config.metrics,
                                  repeats=config.repeats, device=config.device)
            if result.skipped:
                cell = {**base, "status": "skipped", "reason": result.skipped}
            else:
                cell = {**base, "status": "ok", "timed_beside": beside,
                        **cell_record(result, frames, registry.wants(inst, scene.provides))}
                if frames[0].kind == "sequence":
                    cell["sequence_mode"] = ("frame by frame" if inst.per_frame("sequence")
                                             else "temporal")
        except (Exception, SystemExit) as exc:  # noqa: BLE001 - one failing method (or a
            # plugin's sys.exit) must not stop the sweep nor lend it its exit code
            cell = {**base, "status": "error", "error": method_failure(exc),
                    "traceback": traceback.format_exc(limit=5)}
        io.write_json(cell_path(out_path, scene_label, spp, labels[m]), cell)
        written.append(m)
    return written


def _unbuilt(method: str, exc: BaseException) -> str:
    """The line of a cell whose method this process could not build: a pool worker or Ray task
    loads the sweep's plugins afresh (dbench/run/sweep_pool.py), so a plugin file removed or
    broken since the sweep started is refused here, as an edited one is."""
    from .. import plugins

    # an unknown name: the plugins this worker could not load say why
    why = plugins.broken_reason(method) or "; ".join(
        plugins.broken_reason(p.spec) for p in plugins.broken()) or method_failure(exc)
    return f"{method}: not built in this sweep's worker ({why}); not scored: run the sweep again"


def run_group_captured(config: SweepConfig, out: str, scene_name: str, spp: int,
                       method_names: list[str], planned: dict[str, dict] | None = None,
                       beside: int = 0) -> dict[str, list[str]]:
    """:func:`run_group` with the library warnings raised meanwhile kept as lines
    (:mod:`.capture`), so that a worker process's warnings reach the sweep's ``sweep.log``
    instead of the terminal: ``{"written": cell paths, "warnings": lines}``."""
    from .capture import library_warnings

    with library_warnings() as caught:
        written = run_group(config, out, scene_name, spp, method_names, planned, beside)
    return {"written": written, "warnings": list(caught)}


def run_group_with_plugins(plugin_specs: Sequence[str], config: SweepConfig, out: str,
                           scene_name: str, spp: int, method_names: list[str],
                           planned: dict[str, dict] | None = None, most_beside: int = 0,
                           load_lines: Sequence[str] = ()) -> dict[str, list[str]]:
    """:func:`run_group_captured` after loading the parent's plugins (a Ray task's start-up);
    its cells record how many tasks may run beside it on its node, at most ``most_beside``
    (:func:`dbench.run.sweep_pool.ray_beside`). ``load_lines``: as a pool worker's
    (:func:`dbench.run.sweep_pool.worker_start`)."""
    from .. import plugins, registry  # noqa: F401 - the built-in methods before the plugins
    from ..datasets import mitsuba_log

    plugins.worker_init(plugin_specs)
    mitsuba_log.inherit(load_lines)
    return run_group_captured(config, out, scene_name, spp, method_names, planned,
                              sweep_pool.ray_beside(most_beside))


def remove_interrupted_writes(out: Path) -> int:
    """Delete the temporary cell files (``.NAME.json.*.tmp.json``, :func:`dbench.io.atomic_path`)
    that a killed run left in the sweep folder ``out``; returns how many. Readers already skip
    them (their names start with a dot); a resumed sweep removes them so that the folder holds
    exactly one file per cell. One sweep writes to a folder at a time."""
    stale = list(Path(out).glob("cells/*/*/.*.tmp.json"))
    for p in stale:
        p.unlink(missing_ok=True)
    return len(stale)


def run_sweep(config: SweepConfig, out: str | Path, executor: str = "local", workers: int = 1,
              progress: bool = True, warnings_out: list[str] | None = None) -> dict[str, int]:
    """Run (or resume) a sweep; returns counts of computed, already finished and failed cells.
    The library warnings raised while the groups ran, in this process or a worker's, are
    appended to ``warnings_out`` as lines (:mod:`.capture`).

    Every setting and scene is validated and every finished cell's identity checked before
    anything is written or rendered, and every reference the run scores against is rendered
    and found lit before anything is written: a refusal leaves the folder as it was (README.md,
    the ``dbench sweep`` paragraph). The folder is locked for the run (:mod:`.sweep_lock`)
    and the run is recorded in sweep.json's history (:mod:`.sweep_history`) from then on (one
    stopped while its references render wrote nothing, and leaves no entry)."""

    config.validate()
    check_count("--workers", workers)
    sweep_pool.check_executor(executor)
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise DbenchInputError(f"--out {out}: exists and is not a folder")
    check_scenes(config)  # every scene's refusal before the folder, its lock or sweep.json
    with sweep_lock.hold(out):
        to_write = stored_config(out, config, sweep_history.read(out))
        remove_interrupted_writes(out)
        groups, done, skips = plan(config, out)
        if groups and not config.no_cache:  # created only once nothing refused the sweep
            check_cache(config)
        # the last scene checked first, the first group's scene last: a scene file's objects,
        # loaded when it was checked or its reference rendered, then serve its next renders
        # too wherever no other scene's load comes between (mitsuba_env.focus drops them)
        order = list(reversed(dict.fromkeys(g[0] for g in groups)))
        t_refs = render_references(config, order, progress)
        for path, cell in skips:
            io.write_json(path, cell)
        skipped = len(skips)
        run = sweep_history.RunRecord(out, to_write, config, executor, workers, done, skipped)
        # what the run writes is counted from the files (sweep_history.tally): a group stopped
        # half-way, or finished by a pool worker whose result never came back, wrote cells too
        before = sweep_history.snapshot(group_cells(config, out, groups))
        warned = warnings_out if warnings_out is not None else []
        try:
            sweep_pool.execute(groups, (config, str(out)), executor, workers, progress, warned,
                               run_group_captured, run_group_with_plugins)
        except BaseException as exc:
            try:
                run.end("interrupted" if isinstance(exc, KeyboardInterrupt) else "failed",
                        sweep_history.tally(before), error=f"{type(exc).__name__}: {exc}")
            except Exception:  # noqa: BLE001 - the first error is the one to report
                pass
            raise
        written = sweep_history.tally(before)
        run.end("finished", written, t_refs)
    errors = error_cells(config, out)
    return {"computed": written["cells"], "skipped": skipped, "finished_before": done,
            "errors": len(errors), "error_cells": errors}


def check_cache(config: SweepConfig) -> None:
    """Create the sweep's cache folder, or refuse one that cannot be written, naming what named
    it (--cache, $DBENCH_CACHE or the default): the workers share renders through it."""
    from ..datasets.cache import Cache, origin

    try:
        io.ensure_writable_dir(Cache(config.cache).root, origin(config.cache))
    except DbenchInputError as exc:
        if config.cache is not None:  # named by the user
            raise
        raise DbenchInputError(f"{exc}; a sweep's workers share renders through the cache: "
                               f"give --cache a writable folder") from None


def group_cells(config: SweepConfig, out: Path, groups: list) -> list[Path]:
    """The cell files the groups (scene, spp, [methods], identities) of :func:`plan` write."""
    labels = config.labels()
    scene_label = scene_labels(config, out)
    return [cell_path(out, scene_label[s], spp, labels[m]) for s, spp, ms, *_ in groups
            for m in ms]


def error_cells(config: SweepConfig, out: Path) -> list[str]:
    """``scene/spp/method: error`` of every error cell of this sweep's grid (its methods,
    scenes and spp); cells of other grids in the same folder are not this sweep's failures."""
    labels = set(config.labels().values())
    scenes = set(scene_labels(config, out).values())
    return [f"{c.get('scene')}/{c.get('spp')}/{c.get('method')}: {c.get('error', '')}"
            for c in load_cells(out) if c.get("status") == "error" and
            c.get("method") in labels and c.get("spp") in config.spp and
            c.get("scene") in scenes]
