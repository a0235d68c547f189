"""``dbench run``: the command line checked and turned into a :class:`RunRequest`, the run's
folder staged, the scene run (dbench/run/scene_run.py), the headline printed.

The outputs are written into a temporary folder that takes the place of ``--out`` only once
all of them are written, and only then is the table printed (README.md, "Usage";
dbench/report/run_output.py).
"""
from __future__ import annotations

import argparse
import datetime as _dt
import sys
from pathlib import Path

from ..run.scene_run import RunRequest, run_scene
from .args import (_check_common, _default_spp, _scene_of, _writable_cache,
                   check_kind_options, check_lam, method_names, parse_params,
                   warn_left_out)


def cmd_run(args: argparse.Namespace) -> int:
    from ..run.capture import library_warnings

    # from the scene's first reading on: Mitsuba warns about a scene file while it is checked,
    # before anything renders, and those lines belong in run.log too
    with library_warnings() as caught:
        return _run(args, caught)


def _run(args: argparse.Namespace, caught: list[str]) -> int:
    """:func:`cmd_run` with ``caught``, the library warnings so far (dbench/run/capture.py)."""
    from .. import datasets, registry
    from ..run import identity
    from ..report import run_output
    from ..data import check_count

    given = method_names(args.method, "--method")
    names = given or registry.available()
    for n in names:
        registry.method_class(n)  # raises UnknownNameError listing valid names
    scene = _scene_of(args)
    check_kind_options(args, [scene], [args.scene])
    args.spp = _default_spp(scene) if args.spp is None else args.spp
    check_count("--spp", args.spp)
    if args.res is None:
        args.res = datasets.default_res(scene)
    _check_common(args)
    check_lam(args, [scene], [args.scene], [args.spp])
    from ..device import resolve_device
    device = resolve_device(args.device)
    if "noisy" not in names:
        names = ["noisy"] + names
    params = parse_params(args.param or [], names)
    instances = {n: registry.get(n, **params[n]) for n in names}
    labels = {n: identity.label(n, params[n]) for n in names}

    skipped: dict[str, str] = {}
    runnable = []
    for n, m in instances.items():
        ok, why = registry.applies(m, scene.kind, set(scene.provides))
        if ok:
            runnable.append(n)
        else:
            skipped[n] = why
    out = Path(args.out) if args.out else Path("results/runs") / (
        f"{scene.name}_{args.spp}spp_{args.res}px_"
        f"{_dt.datetime.now().strftime('%Y%m%d-%H%M%S')}")
    cache = _writable_cache(args)
    # checked and about to render: "all" says what it leaves out (not before a refusal's line)
    left_out = warn_left_out("--method") if given is None else ""
    request = RunRequest(spp=args.spp, res=args.res, seed=args.seed, seeds=args.seeds,
                         transform=args.transform, lam=args.lam, ref_spp=args.ref_spp,
                         frames=args.frames, bins=args.bins, repeats=args.repeats,
                         quiet=args.quiet, rank_by=args.rank_by,
                         notes=(left_out,) if left_out else ())
    # a failure or Ctrl-C inside the block removes the temporary folder: no partial --out
    with run_output.staged(out) as stage:
        table, failed, summary = run_scene(stage, request, scene, instances, labels, runnable,
                                           skipped, device, cache, caught)
    # printed only now: a reader that goes away (| head) can no longer cost any file
    print()
    print("\n".join(summary))
    if not args.quiet:  # --quiet: the headline alone
        from ..report.terminal import skipped_line
        from ..run.capture import count_text
        for line in (skipped_line({labels.get(n, n): why for n, why in skipped.items()}),
                     count_text(caught) if caught else ""):
            if line:
                print(line)
    print(f"report: {out / 'report.md'}")
    if failed:
        print(f"{len(failed)} method(s) failed: {', '.join(failed)} (see the report)",
              file=sys.stderr)
        return 4
    return 0


__all__ = ["cmd_run"]
