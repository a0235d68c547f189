"""Command line: ``dbench run | sweep | stress | report | list | render | export | bench | train``.

Exit codes: 0 success, 2 unknown names or bad arguments (the valid names are listed) or a
plugin asked for that failed to load (named, with the reason),
3 renderer unavailable.
"""
from __future__ import annotations

import argparse
import ast
import datetime as _dt
import json
import sys
from pathlib import Path
from typing import Any, Sequence


from .errors import DbenchInputError, RendererUnavailableError, UnknownNameError

#: Columns ``--rank-by`` accepts.
RANKABLE = ("relmse", "rmse", "rmse_surface", "relmse_surface", "smape", "smape_surface",
            "psnr", "psnr_surface", "ssim", "ssim_surface", "flip", "flip_surface",
            "rmse_unbiased", "relmse_unbiased")


def _parse_value(text: str) -> Any:
    try:
        return ast.literal_eval(text)
    except (ValueError, SyntaxError):
        return text


def parse_params(items: Sequence[str], method_names: Sequence[str]) -> dict[str, dict[str, Any]]:
    """``key=value`` (every method that has ``key``) or ``method.key=value`` (one method)."""
    from . import methods

    out: dict[str, dict[str, Any]] = {m: {} for m in method_names}
    for item in items:
        if "=" not in item:
            raise DbenchInputError(f"--param: expected key=value or method.key=value, got {item!r}")
        key, value = item.split("=", 1)
        target, _, name = key.rpartition(".")
        value = _parse_value(value)
        if target:
            if target not in out:
                raise DbenchInputError(f"--param {item}: method {target!r} is not in this run "
                                       f"({', '.join(method_names)})")
            if name not in methods.method_class(target).defaults:
                raise DbenchInputError(f"--param {item}: {target} has no parameter {name!r}; "
                                       f"valid: {sorted(methods.method_class(target).defaults)}")
            out[target][name] = value
        else:
            takers = [m for m in method_names if name in methods.method_class(m).defaults]
            if not takers:
                raise DbenchInputError(f"--param {item}: no method of this run has a parameter "
                                       f"{name!r}")
            for m in takers:
                out[m][name] = value
    return out


def _split(text: str) -> list[str]:
    return [t.strip() for t in text.split(",") if t.strip()]


def cmd_list(args: argparse.Namespace) -> int:
    from . import methods
    from .datasets import scenes

    from . import plugins

    if args.methods_only:
        print("\n".join(methods.available()))
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
    print("  (or --scene PATH: a Mitsuba scene file .xml, a Python scene file .py, or a "
          "folder of EXR renders in OIDN's layout)")
    print("\nMethods:")
    for name in methods.available():
        cls = methods.method_class(name)
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


def _summarise_parts(parts: Sequence[str]) -> str:
    """``frame0, frame1, reference0`` → ``frame ×2, reference ×1`` (sequence renders are cached
    per frame); names without a frame number are listed as they are."""
    import re
    from collections import Counter

    counts = Counter(re.sub(r"\d+$", "", p) if re.search(r"\d+$", p) else p for p in parts)
    numbered = {re.sub(r"\d+$", "", p) for p in parts if re.search(r"\d+$", p)}
    return ", ".join(f"{k} ×{v}" if k in numbered else k for k, v in counts.items())


MAX_PARAM_CHARS = 1000


def _ints(text: str, name: str) -> list[int]:
    """``"4,16"`` → [4, 16]; a DbenchInputError naming ``name`` for anything else."""
    out = []
    for t in _split(text):
        try:
            out.append(int(t))
        except ValueError:
            raise DbenchInputError(f"{name}: expected a comma list of integers >= 1, got "
                                   f"{t!r} in {text!r}") from None
    return out


def _check_common(args: argparse.Namespace) -> None:
    """Checks shared by ``run`` and ``sweep``, done before anything renders."""
    from .data import check_count
    from .resolution import parse_res

    for item in args.param or []:
        if len(item) > MAX_PARAM_CHARS:
            raise DbenchInputError(f"--param: {len(item)} characters; at most {MAX_PARAM_CHARS}")
    args.res = parse_res(args.res, "--res")
    for name in ("repeats", "seeds"):
        check_count(f"--{name}", getattr(args, name))
    if args.ref_spp is not None:
        check_count("--ref-spp", args.ref_spp)
    if args.rank_by not in RANKABLE:
        raise DbenchInputError(f"--rank-by: {args.rank_by!r}; valid: {', '.join(RANKABLE)}")
    from .data import check_transform

    try:
        check_transform(args.transform or "box-cox", args.lam)
    except DbenchInputError as exc:
        raise DbenchInputError(f"--transform/--lam: {exc}") from None


def _sequence_window(n_frames: int) -> str:
    from .bench.sequence import WARMUP

    if n_frames > WARMUP:
        return f"1 per frame; metrics and time over frames {WARMUP}-{n_frames - 1} of {n_frames}"
    return (f"1 per frame; metrics and time over all {n_frames} frame(s) (no more frames than "
            f"the {WARMUP}-frame warm-up)")


def _writable_cache(args: argparse.Namespace):
    """The run's cache, checked for writing before anything renders."""
    from . import datasets
    from .io import ensure_writable_dir

    cache = datasets.Cache(args.cache, enabled=not args.no_cache)
    if cache.enabled:
        ensure_writable_dir(cache.root, "--cache")
    return cache


def _scene_of(args: argparse.Namespace):
    """The Scene of ``--scene`` (catalogue name, scene file or folder) with ``--scene-param``."""
    from .datasets import scene_files, scenes

    return scenes.get(args.scene, scene_files.parse_scene_params(args.scene_param))


def _default_spp(scene, fallback: int = 16) -> int:
    """``--spp`` when not given: ``fallback`` for rendered scenes; a folder's only spp (a
    folder with several makes the user choose)."""
    if scene.renders:
        return fallback
    spps = list(scene.info.spps)
    if len(spps) == 1:
        return spps[0]
    raise DbenchInputError(f"--spp: {scene.info.path} holds spp {', '.join(map(str, spps))}; "
                           f"choose one")


def cmd_run(args: argparse.Namespace) -> int:
    from . import datasets, methods
    from .bench import harness, identity, report
    from .bench.formats import markdown_table, write_csv
    from .bench.machine import machine_info
    from .bench.sweep import cell_record, load_seeds
    from .datasets import scenes
    from .data import check_count
    from .io import ensure_writable_dir, write_exr, write_json, write_text

    import pandas as pd

    names = methods.available() if args.method == "all" else _split(args.method)
    for n in names:
        methods.method_class(n)  # raises UnknownNameError listing valid names
    scene = _scene_of(args)
    args.spp = _default_spp(scene) if args.spp is None else args.spp
    check_count("--spp", args.spp)
    if args.res is None:
        args.res = datasets.default_res(scene)
    _check_common(args)
    if "noisy" not in names:
        names = ["noisy"] + names
    params = parse_params(args.param or [], names)
    instances = {n: methods.get(n, **params[n]) for n in names}
    labels = {n: identity.label(n, params[n]) for n in names}

    skipped: dict[str, str] = {}
    runnable = []
    for n, m in instances.items():
        ok, why = m.applies_to(scene.kind, set(scene.provides))
        if ok:
            runnable.append(n)
        else:
            skipped[n] = why
            print(f"skipping {n}: {why}")
    out = Path(args.out) if args.out else Path("results/runs") / (
        f"{scene.name}_{args.spp}spp_{args.res}px_"
        f"{_dt.datetime.now().strftime('%Y%m%d-%H%M%S')}")
    cache = _writable_cache(args)
    ensure_writable_dir(out, "--out")
    needs = set().union(*(instances[n].wants(scene.provides) for n in runnable)) | {
        "reference"} | ({"emitter"} & set(scene.provides))
    frames = load_seeds(scene, args.seed, args.seeds, spp=args.spp, res=args.res, needs=needs,
                        transform=args.transform, lam=args.lam, ref_spp=args.ref_spp,
                        cache=cache, progress=not args.quiet, frames=args.frames,
                        bins=args.bins)
    frame = frames[0]
    is_sequence = frame.kind == "sequence"

    rows, per_seed, outputs = [], [], []
    for n in runnable:
        if not args.quiet:
            print(f"running {labels[n]} ...", flush=True)
        if is_sequence:
            res = harness.run_sequence_cell(instances[n], frames)
        else:
            res = harness.run_cell(instances[n], frames, repeats=args.repeats)
        if res.skipped:
            skipped[n] = res.skipped
            continue
        record = cell_record(res, frames, set(instances[n].needs))
        rows.append({"scene": scene.name, "method": labels[n], "base_method": n,
                     "spp": args.spp, "res": args.res.key, **record,
                     "params": json.dumps(res.params, sort_keys=True, default=str)})
        per_seed += [{"scene": scene.name, "method": labels[n], "spp": args.spp, **r}
                     for r in res.per_seed]
        outputs.append((labels[n], res.sequence if is_sequence else res.output))
        write_exr(out / "images" / f"{identity.file_stem(labels[n])}.exr", {"color": res.output})
    last = frame[len(frame) - 1] if is_sequence else frame
    write_exr(out / "images" / "reference.exr", {"color": last.reference})

    table = pd.DataFrame(rows)
    csv_table = table.drop(columns=[c for c in ("seeds", "times_s", "per_seed")
                                    if c in table.columns])
    write_csv(out / "metrics.csv", csv_table)
    write_csv(out / "metrics_per_seed.csv", pd.DataFrame(per_seed))
    if is_sequence:
        from .bench.sequence import plot_errors, strip
        runs = dict(outputs)
        title = f"{scene.name}, {args.spp} spp, {args.res.text} px, {len(frame)} frames"
        plot_errors(runs, out / "error_per_frame.png", title=title,
                    events=frame.meta.get("events"))
        strip(frame, runs, out / "comparison.png", title=title)
        for n, run in runs.items():
            write_csv(out / f"per_frame_{identity.file_stem(n)}.csv", pd.DataFrame(run.per_frame))
    elif frame.kind == "transient":
        from .bench.transient import write_figures
        write_figures(out, frame, dict(outputs), title=f"{scene.name}, {args.spp} spp")
    else:
        report.comparison_grid(out / "comparison.png", outputs, frame.reference, ev=scene.ev,
                               title=f"{scene.name}, {args.spp} spp, {args.res.text} px")
    info = machine_info()
    seeds = [args.seed + k for k in range(args.seeds)]
    settings = {"scene": scene.name, "kind": scene.kind, "spp": args.spp, "res": args.res.key,
                "seeds": ", ".join(map(str, seeds)),
                "ref_spp": frame.meta.get("ref_spp"),
                "reference seed": frame.meta.get("ref_seed"),
                "reference RMSE (estimated)": frame.meta.get("ref_rmse"),
                "repeats": (_sequence_window(len(frame)) if is_sequence else args.repeats),
                "transform": (f"{frame.stats.transform} (λ = {frame.stats.lam})"
                              if getattr(frame, "stats", None) is not None else "n/a"),
                "variant": frame.meta["versions"]["variant"],
                "render_s": frame.meta.get("render_s"),
                "cache hits": _summarise_parts(frame.meta["cache_hits"]) or "none",
                "rendered": _summarise_parts(frame.meta["rendered"]) or "nothing",
                "method parameters": "; ".join(f"{r['method']}: {r['params']}" for r in rows)}
    write_text(out / "report.md", report.run_report_md(table, settings, info, skipped,
                                                       rank_by=args.rank_by))
    write_json(out / "run.json", {"settings": settings, "machine": info, "skipped": skipped})
    print()
    shown = [c for c in report.RUN_COLUMNS if c in table.columns]
    print(markdown_table(table[shown]))
    print(f"\nreport: {out / 'report.md'}")
    return 0


def cmd_render(args: argparse.Namespace) -> int:
    """Render (or find cached) every buffer of the given scenes, e.g. to warm the cache."""
    from . import datasets
    from .datasets import scene_files, scenes
    from .resolution import parse_res

    params = scene_files.parse_scene_params(args.scene_param)
    names = _split(args.scene) if args.scene != "all" else datasets.available_scenes()
    chosen = [scenes.get(n, params) for n in names]
    sizes = [parse_res(args.res, "--res") if args.res is not None else datasets.default_res(sc)
             for sc in chosen]
    cache = datasets.Cache(args.cache, enabled=not args.no_cache)
    for name, sc, res in zip(names, chosen, sizes):
        frame = datasets.load(sc, spp=args.spp, res=res, seed=args.seed,
                              ref_spp=args.ref_spp, cache=cache)
        print(f"{name}: rendered {frame.meta['rendered'] or 'nothing'}, "
              f"cached {frame.meta['cache_hits'] or 'nothing'}")
    return 0


def cmd_export(args: argparse.Namespace) -> int:
    """Write a scene's renders (noisy at each spp, features, emitter, statistics, reference)
    in the OIDN folder layout that ``--scene DIR`` reads (dbench.datasets.export)."""
    import re

    from . import datasets
    from .data import check_count
    from .datasets.export import export_frame, write_dataset_json
    from .io import ensure_writable_dir
    from .resolution import parse_res

    scene = _scene_of(args)
    if not scene.renders:
        raise DbenchInputError(f"--scene {args.scene}: already a folder of renders")
    if scene.kind == "transient":
        raise DbenchInputError(f"--scene {args.scene}: transient videos have no place in the "
                               f"folder layout; export steady or sequence scenes")
    spps = _ints(args.spp, "--spp")
    for spp in spps:
        check_count("--spp", spp)
    res = parse_res(args.res, "--res") if args.res is not None else datasets.default_res(scene)
    name = args.name or re.sub(r"[^A-Za-z0-9.-]+", "-", scene.name).strip("-") or "scene"
    out = Path(args.out)
    cache = _writable_cache(args)
    ensure_writable_dir(out, "--out")
    needs = set(scene.provides) - {"gradient", "emission"}
    written: list[Path] = []
    ref_spp = None
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
    written.append(write_dataset_json(out, ref_spp=ref_spp, ev=scene.ev,
                                      description=scene.description, scene=scene.name))
    print(f"exported {scene.name} at {res.text} px, spp {', '.join(map(str, spps))}, "
          f"reference {ref_spp} spp: {len(written)} files in {out}")
    return 0


def cmd_bench(args: argparse.Namespace) -> int:
    from .bench import speed
    from .resolution import parse_res

    # --res sets the render benchmark's size (default 256) and, when given, the image size of
    # the method and metric benchmarks (instead of --width/--height)
    if args.res is not None:
        args.res = parse_res(args.res, "--res")
        args.width, args.height = args.res
    if args.what == "render":
        result = speed.bench_render(scene=args.scene, res=args.res or parse_res(256),
                                    spp=args.spp,
                                    repeats=args.repeats)
    elif args.what in ("scene-file", "plugins"):
        from .bench import speed_files
        result = (speed_files.bench_plugin_discovery(repeats=max(args.repeats, 3))
                  if args.what == "plugins" else
                  speed_files.bench_scene_file(res=args.res or parse_res(256), spp=args.spp,
                                               repeats=args.repeats))
        print(speed_files.format_result(result))
        if args.out:
            speed.append_result(args.out, result)
        return 0
    elif args.what == "metrics":
        result = speed.bench_metrics(height=args.height, width=args.width,
                                     repeats=args.repeats)
    else:
        result = speed.bench_method(args.what, height=args.height, width=args.width,
                                    repeats=args.repeats)
    print(speed.format_result(result))
    if args.out:
        speed.append_result(args.out, result)
    return 0


def cmd_sweep(args: argparse.Namespace) -> int:
    from .bench import sweep

    from .datasets import scene_files

    scene_params = scene_files.parse_scene_params(args.scene_param)
    methods_, scenes_ = sweep.resolve_names(args.methods, args.scenes, scene_params)
    res_given = args.res
    args.res = args.res or "128"  # checked here; the sweep's own default is per scene
    _check_common(args)
    params = parse_params(args.param or [], methods_)
    config = sweep.SweepConfig(methods=methods_, scenes=scenes_,
                               spp=_ints(args.spp, "--spp"),
                               res=args.res.key if res_given is not None else None,
                               scene_params=scene_params,
                               ref_spp=args.ref_spp, seed=args.seed, seeds=args.seeds,
                               repeats=args.repeats, rerun=args.rerun,
                               transform=args.transform, lam=args.lam, frames=args.frames,
                               bins=args.bins,
                               params={k: v for k, v in params.items() if v}, cache=args.cache)
    _writable_cache(args)
    counts = sweep.run_sweep(config, args.out, executor=args.executor, workers=args.workers,
                             progress=not args.quiet)
    print(f"sweep {args.out}: {counts['computed']} cells computed, "
          f"{counts['skipped']} not applicable (skipped with the reason), "
          f"{counts['finished_before']} already finished, {counts['errors']} errors")
    return 0 if counts["errors"] == 0 else 1


def cmd_stress(args: argparse.Namespace) -> int:
    from .bench import stress
    from .io import write_text

    from . import methods
    from .io import ensure_writable_dir

    names = _split(args.methods) if args.methods != "all" else None
    for n in names or []:
        methods.method_class(n)
    out = Path(args.out)
    if out.is_dir() or args.out.endswith("/"):
        out = out / "stress.md"  # a folder: the matrix goes into it
    ensure_writable_dir(out.parent, "--out")
    results = stress.run_all(names, progress=not args.quiet)
    text = stress.stress_markdown(results)
    write_text(out, text)
    print("\n".join(text.splitlines()[:3 + len(results) + 4]))
    print(f"written: {out}")
    failed = sum(o.status == "fail" for r in results.values() for o in r.values())
    return 0 if failed == 0 else 1


def cmd_report(args: argparse.Namespace) -> int:
    from .bench import publish

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
    out = publish.publish(results, sweep_dir, rank_by=args.rank_by)
    print(f"written: {out}")
    return 0


def cmd_train(args: argparse.Namespace) -> int:
    """Render (or read cached) procedural training scenes, train, write the ONNX + JSON."""
    from . import datasets
    from .learn.train import run_training

    overrides = {"seed": args.seed}
    if args.steps is not None:
        overrides["steps"] = args.steps
    if args.minutes is not None:
        overrides["max_minutes"] = args.minutes
    if args.width_scale is not None:
        if args.method != "autoencoder":
            raise DbenchInputError("--width-scale: only the autoencoder has widths")
        overrides["width_scale"] = args.width_scale
    if args.sequences and args.method != "autoencoder":
        raise DbenchInputError("--sequences: only the autoencoder is recurrent")
    if args.sequences is None:
        args.sequences = 16 if args.method == "autoencoder" else 0
    run_training(args.method, n_scenes=args.scenes, res=args.res,
                 ref_spp=args.ref_spp or 1024, out_dir=args.out, sequences=args.sequences,
                 cache=datasets.Cache(args.cache, enabled=not args.no_cache), **overrides)
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="dbench", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True)

    def common(sp: argparse.ArgumentParser) -> None:
        sp.add_argument("--cache", default=None, help="cache folder (default $DBENCH_CACHE or "
                        "~/.cache/dbench)")
        sp.add_argument("--no-cache", action="store_true", help="render everything afresh")
        sp.add_argument("--seed", type=int, default=0)
        sp.add_argument("--ref-spp", type=int, default=None,
                        help="reference spp (default $DBENCH_REF_SPP or 4096)")
        sp.add_argument("--scene-param", action="append", metavar="NAME=VALUE",
                        help="a $parameter of a Mitsuba scene file (repeatable)")

    def judged(sp: argparse.ArgumentParser) -> None:
        sp.add_argument("--seeds", type=int, default=1, help="independent noisy renders "
                        "(seeds --seed ... --seed+N-1) scored against one reference; metrics "
                        "are their mean with a 95 %% Student-t interval (one seed: a block "
                        "bootstrap interval)")
        sp.add_argument("--rank-by", default="relmse", help="metric that ranks the methods "
                        "(default relmse, the convention for HDR renders)")

    r = sub.add_parser("run", help="run methods on one scene and write a report")
    r.add_argument("--method", required=True, help="NAME[,NAME...] or all (those that do not "
                   "apply to the scene are skipped with the reason)")
    r.add_argument("--scene", required=True)
    r.add_argument("--spp", type=int, default=None, help="samples per pixel (default 16; a "
                   "folder of renders: its only spp)")
    r.add_argument("--res", default=None, help="image size: N (N×N) or WIDTHxHEIGHT, e.g. "
                   "1280x720 (default 128×128; a scene file: its film's aspect ratio with the "
                   "longer side 128; a folder: its images' size)")
    r.add_argument("--out", default=None, help="output folder (default results/runs/<new>)")
    r.add_argument("--param", action="append", metavar="[METHOD.]KEY=VALUE")
    r.add_argument("--repeats", type=int, default=5, help="timed calls after one warm-up")
    r.add_argument("--transform", default=None, help="sample transform of the statistics "
                   "(default: box-cox for steady scenes, identity for transient ones)")
    r.add_argument("--lam", type=float, default=0.5)
    r.add_argument("--frames", type=int, default=None, help="sequence scenes: frames from the "
                   "start (default all)")
    r.add_argument("--bins", type=int, default=None, help="transient scenes: time bins "
                   "(default the scene's)")
    r.add_argument("--quiet", action="store_true")
    common(r)
    judged(r)
    r.set_defaults(func=cmd_run)

    lp = sub.add_parser("list", help="list scenes and methods")
    lp.add_argument("--methods-only", action="store_true", help="method names, one a line")
    lp.set_defaults(func=cmd_list)

    rp = sub.add_parser("render", help="render or find cached buffers of scenes")
    rp.add_argument("--scene", default="all")
    rp.add_argument("--spp", type=int, default=16)
    rp.add_argument("--res", default=None, help="image size: N (N×N) or WIDTHxHEIGHT "
                    "(default: as for run)")
    common(rp)
    rp.set_defaults(func=cmd_render)

    sw = sub.add_parser("sweep", help="the benchmark grid, resumable")
    sw.add_argument("--methods", default="all", help="all or NAME[,NAME...]")
    sw.add_argument("--scenes", default="all", help="all or NAME[,NAME...]")
    sw.add_argument("--spp", default="4,16,64,256,1024")
    sw.add_argument("--res", default=None, help="image size: N (N×N) or WIDTHxHEIGHT "
                    "(default: each scene's, as for run)")
    sw.add_argument("--out", default="results/sweep")
    sw.add_argument("--executor", choices=("local", "ray"), default="local")
    sw.add_argument("--workers", type=int, default=1, help="local process-pool size")
    sw.add_argument("--repeats", type=int, default=5)
    sw.add_argument("--param", action="append", metavar="[METHOD.]KEY=VALUE")
    sw.add_argument("--transform", default=None, help="sample transform of the statistics "
                    "(default: box-cox for steady scenes, identity for transient ones)")
    sw.add_argument("--lam", type=float, default=0.5)
    sw.add_argument("--frames", type=int, default=None, help="sequence scenes: frames from the "
                    "start (default all)")
    sw.add_argument("--bins", type=int, default=None, help="transient scenes: time bins "
                    "(default the scene's)")
    sw.add_argument("--quiet", action="store_true")
    sw.add_argument("--rerun", action="store_true", help="recompute finished cells whose "
                    "identity (settings, parameters, code, reference) changed instead of "
                    "refusing the sweep")
    common(sw)
    judged(sw)
    sw.set_defaults(func=cmd_sweep)

    st = sub.add_parser("stress", help="every method against adversarial inputs")
    st.add_argument("--methods", default="all")
    st.add_argument("--out", default="results/stress.md")
    st.add_argument("--quiet", action="store_true")
    st.set_defaults(func=cmd_stress)

    rp2 = sub.add_parser("report", help="rebuild results/README.md from result files")
    rp2.add_argument("--results", default="results")
    rp2.add_argument("--sweep", default=None, help="sweep folder (default results/sweep)")
    rp2.add_argument("--rank-by", default="relmse", help="metric that ranks the methods")
    rp2.set_defaults(func=cmd_report)

    ex = sub.add_parser("export", help="write a scene's renders (noisy, features, emitter, "
                        "statistics, reference) as a folder of EXR files in OIDN's layout, "
                        "readable by --scene DIR")
    ex.add_argument("scene", help="catalogue name or scene file")
    ex.add_argument("--out", required=True)
    ex.add_argument("--spp", default="4,16,64", help="comma list of spp")
    ex.add_argument("--res", default=None, help="image size: N or WIDTHxHEIGHT (default: as "
                    "for run)")
    ex.add_argument("--name", default=None, help="file name prefix (default: the scene's "
                    "name)")
    ex.add_argument("--frames", type=int, default=None, help="sequence scenes: frames from "
                    "the start (default all)")
    ex.add_argument("--quiet", action="store_true")
    common(ex)
    ex.set_defaults(func=cmd_export)

    bp = sub.add_parser("bench", help="speed benchmarks with ratios measured in the same run")
    bp.add_argument("what", help="'render' (statistics cost), 'metrics' (the judge against "
                    "the plain metrics), 'scene-file' (an XML scene against the catalogue's), "
                    "'plugins' (entry-point discovery time) or a method name")
    bp.add_argument("--scene", default="cornell")
    bp.add_argument("--res", default=None, help="image size: N (N×N) or WIDTHxHEIGHT, "
                    "e.g. 1280x720 (render: default 256; methods, metrics: default --width "
                    "× --height)")
    bp.add_argument("--spp", type=int, default=64)
    bp.add_argument("--height", type=int, default=720)
    bp.add_argument("--width", type=int, default=1280)
    bp.add_argument("--repeats", type=int, default=3)
    bp.add_argument("--out", default=None, help="append the result to this JSON-lines file")
    bp.set_defaults(func=cmd_bench)

    tp = sub.add_parser("train", help="train nca or autoencoder on procedural training scenes "
                        "rendered here; writes <name>.onnx and <name>.json")
    tp.add_argument("method", choices=["nca", "autoencoder"])
    tp.add_argument("--steps", type=int, default=None, help="optimiser steps (default: config)")
    tp.add_argument("--minutes", type=float, default=None, help="stop after this wall time")
    tp.add_argument("--scenes", type=int, default=48,
                    help="training scenes (nca holds 4 out, autoencoder 2)")
    tp.add_argument("--res", type=int, default=128)
    tp.add_argument("--width-scale", type=float, default=None, help="autoencoder widths factor")
    tp.add_argument("--sequences", type=int, default=None,
                    help="autoencoder: training sequences for the recurrent stage (default 16; "
                    "0: single frames only)")
    tp.add_argument("--out", default=None, help="output folder (default: the method's package "
                    "folder, replacing the shipped weights)")
    common(tp)
    tp.set_defaults(func=cmd_train)
    for sp in sub.choices.values():  # taken out of argv by main() wherever it stands; shown here
        sp.add_argument("--plugin", action="append", metavar="MODULE_OR_FILE.py",
                        help=PLUGIN_HELP)
    return p


PLUGIN_HELP = ("import a module or .py file that registers methods or scenes (repeatable; "
               "also $DBENCH_PLUGINS, os.pathsep-separated; installed entry points are found "
               "without it)")


def split_plugin_args(argv: Sequence[str]) -> tuple[list[str], list[str]]:
    """(argv without ``--plugin X`` / ``--plugin=X``, the plugin specs): the option is taken
    wherever it stands, before or after the subcommand."""
    rest, specs = [], []
    i = 0
    while i < len(argv):
        a = argv[i]
        if a == "--plugin":
            if i + 1 >= len(argv):
                raise DbenchInputError("--plugin: expected a module name or a .py file")
            specs.append(argv[i + 1])
            i += 2
            continue
        if a.startswith("--plugin="):
            specs.append(a.split("=", 1)[1])
        elif a == "--":
            rest += argv[i:]
            break
        else:
            rest.append(a)
        i += 1
    return rest, specs


def _load_plugins(args: argparse.Namespace, specs: Sequence[str]) -> None:
    """Entry points, $DBENCH_PLUGINS and --plugin, before the command runs. A --plugin or
    $DBENCH_PLUGINS entry that fails is an error (exit 2) except for ``list``, which shows it."""
    from . import plugins

    plugins.load_all(specs, strict=args.command != "list")


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    parser.add_argument("--debug", action="store_true", help="show tracebacks (for bug reports)")
    parser.add_argument("--plugin", action="append", metavar="MODULE_OR_FILE.py",
                        help=PLUGIN_HELP)
    argv = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in argv
    argv = [a for a in argv if a != "--debug"]
    try:
        argv, plugin_specs = split_plugin_args(argv)
    except DbenchInputError as exc:
        print(f"dbench: {exc}", file=sys.stderr)
        return 2
    args = parser.parse_args(argv)
    try:
        _load_plugins(args, plugin_specs)
        return args.func(args)
    except UnknownNameError as exc:
        print(f"dbench: {exc}", file=sys.stderr)
        return 2
    except DbenchInputError as exc:
        print(f"dbench: {exc}", file=sys.stderr)
        return 2
    except RendererUnavailableError as exc:
        print(f"dbench: {exc}", file=sys.stderr)
        return 3
    except KeyboardInterrupt:
        print("dbench: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # noqa: BLE001 - one line, not a traceback (--debug shows it)
        if debug:
            raise
        print(f"dbench: internal error: {type(exc).__name__}: {exc} (run again with --debug "
              "for the traceback)", file=sys.stderr)
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
