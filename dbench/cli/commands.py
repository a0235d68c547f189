"""The other commands: ``list``, ``render``, ``export``, ``sweep``, ``stress`` and ``report``
(``run``, ``bench`` and ``train`` have their own modules)."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..errors import DbenchInputError
from .args import (RANKABLE, _check_common, _ints, _scene_of, _writable_cache, check_distinct,
                   check_kind_options, check_lam, method_names, parse_params,
                   warn_left_out)
from .scene_list import refusals_naming, scene_names


def cmd_list(args: argparse.Namespace) -> int:
    from .. import registry
    from ..datasets.scenes import catalogue as scenes
    from ..datasets.scenes.params import describe_all

    from .. import plugins

    if args.methods_only:
        print("\n".join(registry.available()))
        return 0
    origin = {}
    for p in plugins.all_plugins():
        for name in p.provides:
            origin[name] = p.origin
    print("Scenes:")
    for name in scenes.available():
        sc = scenes.get(name)
        print(f"  {name:<12} {sc.kind:<10} {sc.description}"
              + (f"  [plugin: {origin[name]}]" if name in origin else ""))
        if sc.declared:
            print(f"  {'':<12} --scene-param: {describe_all(sc.declared)}")
    print("  (or --scene PATH: a Mitsuba scene file .xml, a Python scene file .py, or a "
          "folder of EXR renders in OIDN's layout)")
    print("\nMethods:")
    for name in registry.available():
        cls = registry.method_class(name)
        kinds = ",".join(sorted(cls.kinds)) + (
            "(+sequence per frame)" if "steady" in cls.kinds and "sequence" not in cls.kinds
            else "")
        print(f"  {name:<12} kinds={kinds:<26} "
              f"needs={','.join(sorted(cls.needs))}"
              + (f" (optional: {','.join(sorted(cls.optional_needs))})"
                 if cls.optional_needs else "")
              + (f"  [plugin: {origin[name]}]" if name in origin else ""))
    bad = plugins.broken()
    if bad:
        print("\nBroken plugins (not loaded):")
        for p in bad:
            print(f"  {p.name:<12} BROKEN  {p.origin}, {p.target}: {p.error}")
    return 0


def cmd_render(args: argparse.Namespace) -> int:
    """Render (or find cached) every buffer of the given scenes, e.g. to warm the cache."""
    from .. import datasets
    from ..datasets.scenes import scoped
    from ..datasets.scenes.build import check_plugin_scene
    from ..resolution import parse_res

    listed = scene_names(args.scene or ["all"], "--scene")
    names = listed or datasets.available_scenes()
    every, own = scoped.split(args.scene_param, names, "--scene")
    chosen = [scoped.scene_of(n, every, own) for n in names]
    if listed is None:  # "all" says which scene plugins it leaves out
        warn_left_out("--scene", scenes=True)
    sizes = [parse_res(args.res, "--res") if args.res is not None else datasets.default_res(sc)
             for sc in chosen]
    cache = _writable_cache(args)  # --cache naming what cannot be written: exit 2

    def load(sc, res):
        return datasets.load(sc, spp=args.spp, res=res, seed=args.seed, ref_spp=args.ref_spp,
                             cache=cache)

    # what a later scene's turn would refuse is refused before the first render (README.md,
    # "Usage"): a folder of renders is only read (its --spp, --ref-spp, --seed), a plugin's
    # steady scene probed
    read = {}
    for k, (sc, res) in enumerate(zip(chosen, sizes)):
        if not sc.renders:
            read[k] = load(sc, res)
        elif sc.kind == "steady":
            check_plugin_scene(sc)
    for k, (name, sc, res) in enumerate(zip(names, chosen, sizes)):
        frame = read[k] if k in read else load(sc, res)
        print(f"{name}: rendered {frame.meta['rendered'] or 'nothing'}, "
              f"cached {frame.meta['cache_hits'] or 'nothing'}")
    return 0


def _kept(caught: list[str], log: Path) -> str:
    """Write ``caught`` (the library warnings a ``--quiet`` command kept off the terminal,
    dbench/run/capture.py) to ``log`` beside the command's output; the line that says so."""
    from ..io import write_text
    from ..run.capture import count_text, log_text

    write_text(log, log_text(caught))
    return count_text(caught, str(log))


def cmd_export(args: argparse.Namespace) -> int:
    """Write a scene's renders (noisy at each spp, features, emitter, statistics, reference)
    in the OIDN folder layout that ``--scene DIR`` reads (dbench.datasets.folders.export).
    Under ``--quiet`` the libraries' warnings (Mitsuba's lines on a scene file) go to
    ``export.log`` in ``--out``, counted on the terminal."""
    import contextlib

    from ..run.capture import library_warnings

    with (library_warnings() if args.quiet else contextlib.nullcontext([])) as caught:
        return _export(args, caught)


def _export(args: argparse.Namespace, caught: list[str]) -> int:
    """:func:`cmd_export` with ``caught``, the library warnings kept so far."""
    import re

    from .. import datasets
    from ..data import check_count
    from ..datasets.folders.export import check_export_folder, export_frame, write_dataset_json
    from ..datasets.references import reference_spp
    from ..datasets.scenes.build import check_plugin_scene
    from ..io import ensure_writable_dir, missing_folders, remove_empty
    from ..resolution import parse_res

    scene = _scene_of(args)
    if not scene.renders:
        raise DbenchInputError(f"--scene {args.scene}: already a folder of renders")
    if scene.kind == "transient":
        raise DbenchInputError(f"--scene {args.scene}: transient videos have no place in the "
                               f"folder layout; export steady or sequence scenes")
    check_kind_options(args, [scene], [args.scene])
    spps = _ints(args.spp, "--spp")
    for spp in spps:
        check_count("--spp", spp)
    res = parse_res(args.res, "--res") if args.res is not None else datasets.default_res(scene)
    name = args.name or re.sub(r"[^A-Za-z0-9.-]+", "-", scene.name).strip("-") or "scene"
    out = Path(args.out)
    # what rendering would refuse is refused before --out exists (README.md, "Usage"), in
    # datasets.load's order: a plugin's steady scene's Mitsuba types and film filter, then
    # the film's size (the fingerprint builds the scene's dictionary at this size and renders
    # nothing)
    if scene.kind == "steady":
        check_plugin_scene(scene)
    fingerprint = datasets.scene_fingerprint(scene, res)
    check_export_folder(out, scene=scene.name, ev=scene.ev, fingerprint=fingerprint,
                        ref_spp=(int(args.ref_spp or reference_spp())
                                 if "reference" in scene.provides else None))
    cache = _writable_cache(args)
    created = missing_folders(out)
    ensure_writable_dir(out, "--out")
    needs = set(scene.provides) - {"gradient", "emission"}
    written: list[Path] = []
    ref_spp = None
    try:
        for i, spp in enumerate(spps):
            data = datasets.load(scene, spp=spp, res=res, needs=needs, seed=args.seed,
                                 ref_spp=args.ref_spp, cache=cache, progress=not args.quiet,
                                 frames=args.frames)
            frames = list(data) if data.kind == "sequence" else [data]
            ref_spp = data.meta.get("ref_spp", ref_spp)
            for k, frame in enumerate(frames):
                written += export_frame(frame, out, name, spp,
                                        frame_index=k if data.kind == "sequence" else None,
                                        write_reference=(i == 0))
    except DbenchInputError:
        # a refusal only the load makes (a sequence's --frames) comes before the first file:
        # the folders this command created go again, as an empty --out says nothing
        if not written:
            remove_empty(created)
        raise
    written.append(write_dataset_json(out, ref_spp=ref_spp, ev=scene.ev,
                                      description=scene.description, scene=scene.name,
                                      fingerprint=fingerprint))
    print(f"exported {scene.name} at {res.text} px, spp {', '.join(map(str, spps))}, "
          f"reference {ref_spp} spp: {len(written)} files in {out}")
    if caught:
        print(_kept(caught, out / "export.log"))
    return 0


def cmd_sweep(args: argparse.Namespace) -> int:
    from ..run.capture import library_warnings

    # from the scenes' first reading on: Mitsuba warns about a scene file while it is checked,
    # and those lines belong in sweep.log too
    with library_warnings() as caught, refusals_naming("--scenes"):
        return _sweep(args, caught)


def _sweep(args: argparse.Namespace, caught: list[str]) -> int:
    """:func:`cmd_sweep` with ``caught``, the library warnings so far (dbench/run/capture.py)."""
    from ..run import sweep
    from ..run.sweep_names import scene_place
    from ..datasets.scenes import catalogue, scoped

    if args.workers is not None and args.executor == "ray":
        raise DbenchInputError(f"--workers {args.workers}: the local executor's pool size; "
                               f"--executor ray runs the cells on the Ray cluster's workers")
    args.workers = 1 if args.workers is None else args.workers
    given = method_names(args.methods or ["all"], "--methods")
    listed = scene_names(args.scenes or ["all"], "--scenes")
    # NAME=VALUE for every scene, SCENE:NAME=VALUE for one (SCENE as written in --scenes)
    scene_params, by_scene = scoped.split(args.scene_param, listed or catalogue.available(),
                                          "--scenes")
    try:
        methods_, scenes_ = sweep.resolve_names(given or "all", listed or "all", scene_params,
                                                by_scene)
    except DbenchInputError as exc:  # a value for every scene that one of them cannot take
        several = listed is None or len(listed) > 1
        if not (scene_params and several and str(exc).startswith("--scene-param")):
            raise
        raise DbenchInputError(f"{exc}; --scene-param SCENE:NAME=VALUE gives a value to one "
                               f"scene only") from None
    scene_objs = [scoped.scene_of(n, scene_params, by_scene) for n in scenes_]
    check_kind_options(args, scene_objs, scenes_)
    res_given = args.res
    args.res = args.res or "128"  # checked here; the sweep's own default is per scene
    _check_common(args)
    spps = _ints(args.spp, "--spp")
    check_lam(args, scene_objs, scenes_, spps)
    params = parse_params(args.param or [], methods_)
    config = sweep.SweepConfig(methods=methods_, scenes=scenes_, spp=spps,
                               res=args.res.key if res_given is not None else None,
                               scene_params=scene_params, scene_params_by_scene=by_scene,
                               ref_spp=args.ref_spp, seed=args.seed, seeds=args.seeds,
                               repeats=args.repeats, rerun=args.rerun,
                               transform=args.transform, lam=args.lam, frames=args.frames,
                               bins=args.bins,
                               params={k: v for k, v in params.items() if v}, cache=args.cache,
                               no_cache=args.no_cache, device=args.device,
                               normal_encoding=args.normal_encoding)
    # one scene named two ways (a.xml and ./a.xml, a folder and DIR/VIEW of its one view) would
    # be swept once under one label, as if given once
    check_distinct([scene_place(config, s) for s in scenes_], "--scenes",
                   " ".join(args.scenes or ["all"]), scenes_)
    from ..run.capture import count_text, log_text
    # the cache is checked (and created) by run_sweep once nothing refused the sweep
    from_groups: list[str] = []  # the groups' warnings, every worker's included
    # checked: "all" says what it leaves out, here and in the run's entry for the report
    config.notes = [line for line in (warn_left_out("--methods") if given is None else "",
                                      warn_left_out("--scenes", scenes=True)
                                      if listed is None else "") if line]
    counts = sweep.run_sweep(config, args.out, executor=args.executor,
                             workers=args.workers, progress=not args.quiet,
                             warnings_out=from_groups)
    print(_sweep_summary(args.out, config, args.rank_by, quiet=args.quiet))
    from ..report.formats import counted

    print(f"sweep {args.out}: {counted(counts['computed'], 'cell')} computed, "
          f"{counts['skipped']} not applicable, "
          f"{counts['finished_before']} already finished, {counted(counts['errors'], 'error')}")
    caught = list(caught) + from_groups
    if caught:
        from ..io import write_text
        write_text(Path(args.out) / "sweep.log", log_text(caught))
        if not args.quiet:
            print(count_text(caught).replace("run.log", "sweep.log"))
    for line in counts["error_cells"][:3]:  # named, not only counted (cells/ holds them all)
        print(f"error: {line[:300]}", file=sys.stderr)
    if counts["errors"] > 3:
        print(f"error: and {counts['errors'] - 3} more error cells", file=sys.stderr)
    return 0 if counts["errors"] == 0 else 4


def _sweep_summary(out: str, config, rank_by: str, quiet: bool) -> str:
    """The sweep's headline: per scene, the ranking and the verdicts of its README at the
    headline spp, and (unless ``quiet``) the skipped methods grouped by reason, over this
    sweep's grid only (dbench/report/terminal.py); a warning where the folder's other cells of
    its labels and scenes were computed with other settings (a ``--rerun`` over part of it)."""
    from ..report import cells as sweep_cells, terminal
    from ..run.sweep_names import scene_labels

    labels = set(config.labels().values())
    scenes = set(scene_labels(config, out).values())
    beside = [c for c in sweep_cells.load_cells(out) if isinstance(c, dict)
              and c.get("method") in labels and c.get("scene") in scenes]
    cells = [c for c in beside if c.get("spp") in config.spp]
    return "\n".join(terminal.sweep_summary(cells, rank_by, skips=not quiet, beside=beside))


def cmd_stress(args: argparse.Namespace) -> int:
    from ..stress import runner as stress
    from ..io import write_text

    from .. import registry
    from ..io import ensure_writable_dir

    names = method_names(args.methods or ["all"], "--methods")
    for n in names or []:
        registry.method_class(n)
    out = Path(args.out)
    if out.is_dir() or args.out.endswith("/"):
        out = out / "stress.md"  # a folder: the matrix goes into it
    ensure_writable_dir(out.parent, "--out")
    if names is None:  # checked: "all" says what it leaves out
        warn_left_out("--methods")
    import contextlib

    from ..stress.device import run_device_forms
    from ..run.capture import library_warnings
    # the hostile cases make libraries warn (NaN, Inf, 3e38 inputs): --quiet counts them
    with (library_warnings() if args.quiet else contextlib.nullcontext([])) as caught:
        results = stress.run_all(names, progress=not args.quiet)
        # each device path in its CPU-testable form, as a row of its own (docs/gpu.md §2)
        results.update(run_device_forms(names, progress=not args.quiet))
    from ..stress.contract import contract_markdown
    text = stress.stress_markdown(results) + "\n" + contract_markdown()
    write_text(out, text)
    print("\n".join(text.splitlines()[:3 + len(results) + 4]))
    print(f"written: {out}")
    if caught:  # kept beside the matrix: stress.md's stress.log
        print("on the hostile inputs: " + _kept(caught, out.with_suffix(".log")))
    failed = sum(o.status == "fail" for r in results.values() for o in r.values())
    return 0 if failed == 0 else 4


def cmd_report(args: argparse.Namespace) -> int:
    from ..report import publish

    if args.rank_by not in RANKABLE:
        raise DbenchInputError(f"--rank-by: {args.rank_by!r}; valid: {', '.join(RANKABLE)}")
    results = Path(args.results)
    if not results.is_dir():
        raise DbenchInputError(f"--results {results}: no such folder")
    sweep_dir = Path(args.sweep) if args.sweep else results / "sweep"
    if not (sweep_dir / "sweep.json").is_file():
        raise DbenchInputError(f"--sweep {sweep_dir}: not a sweep folder (no sweep.json)")
    try:
        sweep_dir.resolve().relative_to(results.resolve())
    except ValueError:
        raise DbenchInputError(f"--sweep {sweep_dir}: must lie inside --results {results} "
                               "(the report links to it)") from None
    if results.is_absolute() != sweep_dir.is_absolute():  # one relative, one not: the report
        results, sweep_dir = results.absolute(), sweep_dir.absolute()  # links one to the other
    from ..run import sweep_history

    from ..run.capture import library_warnings

    for folder in [sweep_dir, *publish.extra_sweeps(results, sweep_dir)]:
        sweep_history.read(folder)  # a damaged sweep.json: one line, as `sweep` says it
    # the libraries' warnings (matplotlib's missing glyphs for a name its font lacks) are one
    # line, as `run` and `sweep` count theirs, never their source lines on the terminal
    with library_warnings() as caught:
        out = publish.publish(results, sweep_dir, rank_by=args.rank_by)
    print(f"written: {out}")
    if caught:
        seen = list(dict.fromkeys(ln.split(": ", 1)[-1] for ln in caught))
        print(f"{len(caught)} library warning{'s' if len(caught) != 1 else ''} while writing: "
              + "; ".join(seen[:3]) + (f"; and {len(seen) - 3} more" if len(seen) > 3 else ""),
              file=sys.stderr)
    return 0
