"""Command line: ``dbench run | sweep | stress | report | list | render | bench | train``.

Exit codes: 0 success, 2 unknown names or bad arguments (the valid names are listed),
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

    if args.methods_only:
        print("\n".join(methods.available()))
        return 0
    print("Scenes:")
    for name in scenes.available():
        sc = scenes.get(name)
        print(f"  {name:<12} {sc.kind:<10} {sc.description}")
    print("\nMethods:")
    for name in methods.available():
        cls = methods.method_class(name)
        print(f"  {name:<12} kinds={','.join(sorted(cls.kinds)):<26} "
              f"needs={','.join(sorted(cls.needs))}")
    return 0


def _summarise_parts(parts: Sequence[str]) -> str:
    """``frame0, frame1, reference0`` → ``frame ×2, reference ×1`` (sequence renders are cached
    per frame); names without a frame number are listed as they are."""
    import re
    from collections import Counter

    counts = Counter(re.sub(r"\d+$", "", p) if re.search(r"\d+$", p) else p for p in parts)
    numbered = {re.sub(r"\d+$", "", p) for p in parts if re.search(r"\d+$", p)}
    return ", ".join(f"{k} ×{v}" if k in numbered else k for k, v in counts.items())


def cmd_run(args: argparse.Namespace) -> int:
    from . import datasets, methods
    from .bench import harness, report
    from .datasets import scenes
    from .bench.sequence import WARMUP
    from .io import write_exr, write_json, write_text

    import pandas as pd

    names = methods.available() if args.method == "all" else _split(args.method)
    for n in names:
        methods.method_class(n)  # raises UnknownNameError listing valid names
    scene = scenes.get(args.scene)
    if "noisy" not in names:
        names = ["noisy"] + names
    params = parse_params(args.param or [], names)
    instances = {n: methods.get(n, **params[n]) for n in names}

    skipped: dict[str, str] = {}
    runnable = []
    for n, m in instances.items():
        ok, why = m.applies_to(scene.kind, set(scene.provides))
        if ok:
            runnable.append(n)
        else:
            skipped[n] = why
            print(f"skipping {n}: {why}")
    needs = set().union(*(instances[n].needs for n in runnable)) | {"reference"}
    cache = datasets.Cache(args.cache, enabled=not args.no_cache)
    frame = datasets.load(scene, spp=args.spp, res=args.res, needs=needs, seed=args.seed,
                          transform=args.transform, lam=args.lam, ref_spp=args.ref_spp,
                          cache=cache, progress=not args.quiet, frames=args.frames,
                          bins=args.bins)
    is_sequence = frame.kind == "sequence"
    out = Path(args.out) if args.out else Path("results/runs") / (
        f"{scene.name}_{args.spp}spp_{args.res}px_"
        f"{_dt.datetime.now().strftime('%Y%m%d-%H%M%S')}")
    out.mkdir(parents=True, exist_ok=True)

    rows, outputs = [], []
    for n in runnable:
        if not args.quiet:
            print(f"running {n} ...", flush=True)
        if is_sequence:
            res = harness.run_sequence_cell(instances[n], frame)
        else:
            res = harness.run_cell(instances[n], frame, repeats=args.repeats)
        if res.skipped:
            skipped[n] = res.skipped
            continue
        rows.append({"scene": scene.name, "method": n, "spp": args.spp, "res": args.res,
                     **res.metrics, "time_s": res.time_s, "n_nonfinite": res.n_nonfinite,
                     "params": json.dumps(res.params, sort_keys=True, default=str)})
        outputs.append((n, res.sequence if is_sequence else res.output))
        write_exr(out / "images" / f"{n}.exr", {"color": res.output})
    last = frame[len(frame) - 1] if is_sequence else frame
    write_exr(out / "images" / "reference.exr", {"color": last.reference})

    table = pd.DataFrame(rows)
    report.write_csv(out / "metrics.csv", table)
    if is_sequence:
        from .bench.sequence import plot_errors, strip
        runs = dict(outputs)
        title = f"{scene.name}, {args.spp} spp, {args.res} px, {len(frame)} frames"
        plot_errors(runs, out / "error_per_frame.png", title=title,
                    events=frame.meta.get("events"))
        strip(frame, runs, out / "comparison.png", title=title)
        for n, run in runs.items():
            report.write_csv(out / f"per_frame_{n}.csv", pd.DataFrame(run.per_frame))
    elif frame.kind == "transient":
        from .bench.transient import write_figures
        write_figures(out, frame, dict(outputs), title=f"{scene.name}, {args.spp} spp")
    else:
        report.comparison_grid(out / "comparison.png", outputs, frame.reference, ev=scene.ev,
                               title=f"{scene.name}, {args.spp} spp, {args.res} px")
    info = harness.machine_info()
    settings = {"scene": scene.name, "kind": scene.kind, "spp": args.spp, "res": args.res,
                "seed": args.seed,
                "ref_spp": frame.meta.get("ref_spp"),
                "repeats": (f"1 per frame; metrics and time over frames ≥ {WARMUP} of "
                            f"{len(frame)}" if is_sequence else args.repeats),
                "transform": (f"{frame.stats.transform} (λ = {frame.stats.lam})"
                              if getattr(frame, "stats", None) is not None else "n/a"),
                "variant": frame.meta["versions"]["variant"],
                "render_s": frame.meta.get("render_s"),
                "cache hits": _summarise_parts(frame.meta["cache_hits"]) or "none",
                "rendered": _summarise_parts(frame.meta["rendered"]) or "nothing",
                "method parameters": "; ".join(f"{r['method']}: {r['params']}" for r in rows)}
    write_text(out / "report.md", report.run_report_md(table, settings, info, skipped))
    write_json(out / "run.json", {"settings": settings, "machine": info, "skipped": skipped})
    print()
    print(report.markdown_table(table[[c for c in report.RUN_COLUMNS if c in table.columns]]))
    print(f"\nreport: {out / 'report.md'}")
    return 0


def cmd_render(args: argparse.Namespace) -> int:
    """Render (or find cached) every buffer of the given scenes, e.g. to warm the cache."""
    from . import datasets

    cache = datasets.Cache(args.cache, enabled=not args.no_cache)
    for name in _split(args.scene) if args.scene != "all" else datasets.available_scenes():
        frame = datasets.load(name, spp=args.spp, res=args.res, seed=args.seed,
                              ref_spp=args.ref_spp, cache=cache)
        print(f"{name}: rendered {frame.meta['rendered'] or 'nothing'}, "
              f"cached {frame.meta['cache_hits'] or 'nothing'}")
    return 0


def cmd_bench(args: argparse.Namespace) -> int:
    from .bench import speed

    if args.what == "render":
        result = speed.bench_render(scene=args.scene, res=args.res, spp=args.spp,
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

    methods_, scenes_ = sweep.resolve_names(args.methods, args.scenes)
    params = parse_params(args.param or [], methods_)
    config = sweep.SweepConfig(methods=methods_, scenes=scenes_,
                               spp=[int(s) for s in _split(args.spp)], res=args.res,
                               ref_spp=args.ref_spp, seed=args.seed, repeats=args.repeats,
                               transform=args.transform, lam=args.lam, frames=args.frames,
                               bins=args.bins,
                               params={k: v for k, v in params.items() if v}, cache=args.cache)
    counts = sweep.run_sweep(config, args.out, executor=args.executor, workers=args.workers,
                             progress=not args.quiet)
    print(f"sweep {args.out}: {counts['computed']} cells computed, "
          f"{counts['skipped']} not applicable (skipped with the reason), "
          f"{counts['finished_before']} already finished, {counts['errors']} errors")
    return 0 if counts["errors"] == 0 else 1


def cmd_stress(args: argparse.Namespace) -> int:
    from .bench import stress
    from .io import write_text

    names = _split(args.methods) if args.methods != "all" else None
    results = stress.run_all(names, progress=not args.quiet)
    text = stress.stress_markdown(results)
    write_text(args.out, text)
    print("\n".join(text.splitlines()[:3 + len(results) + 4]))
    print(f"written: {args.out}")
    failed = sum(o.status == "fail" for r in results.values() for o in r.values())
    return 0 if failed == 0 else 1


def cmd_report(args: argparse.Namespace) -> int:
    from .bench import publish

    out = publish.publish(args.results, args.sweep)
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

    r = sub.add_parser("run", help="run methods on one scene and write a report")
    r.add_argument("--method", required=True, help="NAME[,NAME...] or all (those that do not "
                   "apply to the scene are skipped with the reason)")
    r.add_argument("--scene", required=True)
    r.add_argument("--spp", type=int, default=16)
    r.add_argument("--res", type=int, default=128)
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
    r.set_defaults(func=cmd_run)

    lp = sub.add_parser("list", help="list scenes and methods")
    lp.add_argument("--methods-only", action="store_true", help="method names, one a line")
    lp.set_defaults(func=cmd_list)

    rp = sub.add_parser("render", help="render or find cached buffers of scenes")
    rp.add_argument("--scene", default="all")
    rp.add_argument("--spp", type=int, default=16)
    rp.add_argument("--res", type=int, default=128)
    common(rp)
    rp.set_defaults(func=cmd_render)

    sw = sub.add_parser("sweep", help="the benchmark grid, resumable")
    sw.add_argument("--methods", default="all", help="all or NAME[,NAME...]")
    sw.add_argument("--scenes", default="all", help="all or NAME[,NAME...]")
    sw.add_argument("--spp", default="4,16,64,256,1024")
    sw.add_argument("--res", type=int, default=128)
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
    common(sw)
    sw.set_defaults(func=cmd_sweep)

    st = sub.add_parser("stress", help="every method against adversarial inputs")
    st.add_argument("--methods", default="all")
    st.add_argument("--out", default="results/stress.md")
    st.add_argument("--quiet", action="store_true")
    st.set_defaults(func=cmd_stress)

    rp2 = sub.add_parser("report", help="rebuild results/README.md from result files")
    rp2.add_argument("--results", default="results")
    rp2.add_argument("--sweep", default=None, help="sweep folder (default results/sweep)")
    rp2.set_defaults(func=cmd_report)

    bp = sub.add_parser("bench", help="speed benchmarks with ratios measured in the same run")
    bp.add_argument("what", help="'render' (statistics cost) or a method name")
    bp.add_argument("--scene", default="cornell")
    bp.add_argument("--res", type=int, default=256)
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
    return p


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
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


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
