"""The argument parser of every command (``--help`` texts included)."""
from __future__ import annotations

import argparse

from ..options import Parser
from .args import normal_encoding_arg, seed_arg
from .bounds import count, integer, number, ref_count
from .bench import cmd_bench
from .commands import cmd_export, cmd_list, cmd_render, cmd_report, cmd_stress, cmd_sweep
from .guard import command
from .run import cmd_run
from .train import cmd_train

#: The first line of ``dbench --help`` (the first line of the package's docstring).
DESCRIPTION = ("Command line: ``dbench run | sweep | stress | report | list | render | export | "
               "bench | train``.")
#: run's and sweep's --param (dbench.cli.args.parse_params).
PARAM_HELP = ("KEY=VALUE: a parameter of every method that has KEY; METHOD.KEY=VALUE: of that "
              "method, over KEY=VALUE (repeatable)")
PLUGIN_HELP = ("import a module or .py file that registers methods or scenes (repeatable; "
               "also $DBENCH_PLUGINS, os.pathsep-separated; installed entry points are found "
               "without it)")


def build_parser() -> argparse.ArgumentParser:
    p = Parser(prog="dbench", description=DESCRIPTION)
    sub = p.add_subparsers(dest="command", required=True, parser_class=Parser)

    def common(sp: argparse.ArgumentParser, train: bool = False) -> None:
        sp.add_argument("--cache", default=None, help="cache folder (default $DBENCH_CACHE or "
                        "~/.cache/dbench)")
        sp.add_argument("--no-cache", action="store_true", help="render everything afresh")
        if train:  # its renders have fixed seeds and a reference spp of their own
            # (dbench.cli.train: args.ref_spp or 2048); its procedural scenes take no
            # --scene-param
            sp.add_argument("--seed", type=seed_arg, default=0, help="seed of the training "
                            "(nca; the autoencoder's stage 1), in [0, 4294967295]; the "
                            "training renders' seeds are fixed")
            sp.add_argument("--ref-spp", type=ref_count, default=None,
                            help="reference spp of the training scenes (default 2048; "
                            "$DBENCH_REF_SPP does not apply)")
            return
        sp.add_argument("--seed", type=seed_arg, default=0, help="base seed of the noisy "
                        "renders and of the reference, in [0, 4294967295]")
        sp.add_argument("--ref-spp", type=ref_count, default=None,
                        help="reference spp (default $DBENCH_REF_SPP or 4096)")
        sp.add_argument("--scene-param", action="append", metavar="[SCENE:]NAME=VALUE",
                        help="a $parameter of a Mitsuba scene file, or a parameter a "
                        "catalogue scene declares (dbench list shows them; e.g. g=0.5, "
                        "emission=step on the transient scenes), for every scene; "
                        "SCENE:NAME=VALUE for that scene only, named as written in the "
                        "scene option (repeatable)")

    def judged(sp: argparse.ArgumentParser) -> None:
        sp.add_argument("--seeds", type=count, default=1, help="independent noisy renders "
                        "(seeds --seed ... --seed+N-1) scored against one reference; metrics "
                        "are their mean with a 95 %% Student-t interval (one seed: a block "
                        "bootstrap interval)")
        sp.add_argument("--rank-by", default="relmse", help="metric that ranks the methods "
                        "(default relmse, the convention for HDR renders)")

    r = sub.add_parser("run", help="run methods on one scene and write a report")
    r.add_argument("--method", required=True, action="append", help="NAME[,NAME...] or all "
                   "(those that do not apply to the scene are skipped with the reason); "
                   "repeatable, each list adding its methods")
    r.add_argument("--scene", required=True, help="one scene: a catalogue name, "
                   "a scene file or a folder of renders (dbench sweep --scenes takes several)")
    r.add_argument("--spp", type=count, default=None, help="samples per pixel (default 16; a "
                   "folder of renders: its only spp)")
    r.add_argument("--res", default=None, help="image size: N (N×N) or WIDTHxHEIGHT, e.g. "
                   "1280x720 (default 128×128; a scene file: its film's aspect ratio with the "
                   "longer side 128; a folder: its images' size)")
    r.add_argument("--out", default=None, help="output folder (default results/runs/<new>); "
                   "written whole or not at all, and a folder that is not an earlier run's is "
                   "refused")
    r.add_argument("--param", action="append", metavar="[METHOD.]KEY=VALUE", help=PARAM_HELP)
    r.add_argument("--repeats", type=count, default=5, help="timed calls of each method after "
                   "one warm-up")
    r.add_argument("--transform", default=None, help="sample transform of the statistics "
                   "(default: box-cox for steady scenes, identity for transient ones)")
    r.add_argument("--lam", type=number, default=None, help="λ of box-cox and yeo-johnson "
                   "(default 0.5; refused where no scene's transform takes one)")
    r.add_argument("--frames", type=count, default=None, help="sequence scenes: frames from the "
                   "start (default all)")
    r.add_argument("--bins", type=count, default=None, help="transient scenes: time bins "
                   "(default the scene's)")
    _normal_encoding_argument(r)
    r.add_argument("--quiet", action="store_true", help="print the headline alone: no progress "
                   "bars, per-method lines, skipped line or library warnings (the warnings are "
                   "kept in run.log all the same)")
    _device_argument(r)
    common(r)
    judged(r)
    r.set_defaults(func=cmd_run)

    lp = sub.add_parser("list", help="list scenes and methods")
    lp.add_argument("--methods-only", action="store_true", help="print the method names "
                    "alone, one a line (no scenes, kinds or needs)")
    lp.set_defaults(func=cmd_list)

    rp = sub.add_parser("render", help="render or find cached buffers of scenes")
    rp.add_argument("--scene", "--scenes", action="append", default=None,
                    metavar="all|NAME[,NAME...]",
                    help="all (default), or NAME[,NAME...] as sweep --scenes takes them; "
                    "repeatable, each list adding its scenes")
    rp.add_argument("--spp", type=count, default=16, help="samples per pixel of the noisy "
                    "renders")
    rp.add_argument("--res", default=None, help="image size: N (N×N) or WIDTHxHEIGHT "
                    "(default: as for run)")
    common(rp)
    rp.set_defaults(func=cmd_render)

    sw = sub.add_parser("sweep", help="the benchmark grid, resumable")
    # --method and --scene as run and render spell them: the same options
    sw.add_argument("--methods", "--method", action="append", default=None,
                    metavar="all|NAME[,NAME...]", help="all (default) or NAME[,NAME...]; "
                    "repeatable, each list adding its methods")
    sw.add_argument("--scenes", "--scene", action="append", default=None,
                    metavar="all|NAME[,NAME...]",
                    help="all (default), or catalogue names, scene files (.xml, .py) and "
                    "folders of renders; repeatable, each list adding its scenes; a path that "
                    "exists is one scene even when its name holds a comma")
    sw.add_argument("--spp", default="4,16,64,256,1024", help="comma list of samples per "
                    "pixel, each a column of the grid")
    sw.add_argument("--res", default=None, help="image size: N (N×N) or WIDTHxHEIGHT "
                    "(default: each scene's, as for run)")
    sw.add_argument("--out", default="results/sweep", help="the sweep's folder: its cells "
                    "are reused where their identity matches; one sweep at a time holds it")
    sw.add_argument("--executor", choices=("local", "ray"), default="local",
                    help="where the cells run: local (a process pool, --workers) or ray (Ray "
                    "tasks on the Ray cluster)")
    sw.add_argument("--workers", type=integer, default=None, help="local process-pool size "
                    "(default 1; with more, cells are timed side by side and their time_s "
                    "includes the contention, which the cells record and the reports say; "
                    "--executor ray runs the cells on the cluster's workers)")
    sw.add_argument("--repeats", type=count, default=5, help="timed calls of each method "
                    "after one warm-up, in every cell")
    sw.add_argument("--param", action="append", metavar="[METHOD.]KEY=VALUE",
                    help=PARAM_HELP + "; a method given other values than its defaults is its "
                    "own series, labelled with them (jbf[radius=3])")
    sw.add_argument("--transform", default=None, help="sample transform of the statistics "
                    "(default: box-cox for steady scenes, identity for transient ones)")
    sw.add_argument("--lam", type=number, default=None, help="λ of box-cox and yeo-johnson "
                    "(default 0.5; refused where no scene's transform takes one)")
    sw.add_argument("--frames", type=count, default=None, help="sequence scenes: frames from the "
                    "start (default all)")
    sw.add_argument("--bins", type=count, default=None, help="transient scenes: time bins "
                    "(default the scene's)")
    _normal_encoding_argument(sw, "the sweep's folders of renders")
    sw.add_argument("--quiet", action="store_true", help="no progress bars, skipped lines or "
                    "library warnings on the terminal (the warnings are kept in sweep.log all "
                    "the same)")
    _device_argument(sw)
    sw.add_argument("--rerun", action="store_true", help="recompute finished cells whose "
                    "identity (settings, parameters, code, reference) changed instead of "
                    "refusing the sweep")
    common(sw)
    judged(sw)
    sw.set_defaults(func=cmd_sweep)

    st = sub.add_parser("stress", help="every method against adversarial inputs")
    st.add_argument("--methods", action="append", default=None, metavar="all|NAME[,NAME...]",
                    help="all (default) or NAME[,NAME...]; repeatable, each list adding its "
                    "methods")
    st.add_argument("--out", default="results/stress.md", help="the Markdown file the "
                    "matrix is written to (a folder, or a path ending in /: stress.md in it)")
    st.add_argument("--quiet", action="store_true", help="no progress lines; the warnings the "
                    "hostile inputs raise go to stress.log beside the matrix, counted in one "
                    "line")
    st.set_defaults(func=cmd_stress)

    rp2 = sub.add_parser("report", help="rebuild results/README.md from result files")
    rp2.add_argument("--results", default="results", help="the results folder: its result "
                     "files are read and its README.md (and the pages beside it) written")
    rp2.add_argument("--sweep", default=None, help="the sweep folder of the report's tables, "
                     "inside --results (default: --results's sweep folder)")
    rp2.add_argument("--rank-by", default="relmse", help="metric that ranks the methods")
    rp2.set_defaults(func=cmd_report)

    ex = sub.add_parser("export", help="write a scene's renders (noisy, features, emitter, "
                        "statistics, reference) as a folder of EXR files in OIDN's layout, "
                        "readable by --scene DIR")
    ex.add_argument("scene", help="catalogue name or scene file")
    ex.add_argument("--out", required=True, help="the folder written: new, empty, or an "
                    "earlier export of the same scene at the same settings (other spp are "
                    "added beside it)")
    ex.add_argument("--spp", default="4,16,64", help="comma list of spp")
    ex.add_argument("--res", default=None, help="image size: N or WIDTHxHEIGHT (default: as "
                    "for run)")
    ex.add_argument("--name", default=None, help="file name prefix (default: the scene's "
                    "name, characters other than letters, digits, . and - made -)")
    ex.add_argument("--frames", type=count, default=None, help="sequence scenes: frames from "
                    "the start (default all)")
    ex.add_argument("--quiet", action="store_true", help="no progress bars; the libraries' "
                    "warnings (Mitsuba's on a scene file) go to export.log in --out, counted in "
                    "one line")
    common(ex)
    ex.set_defaults(func=cmd_export)

    bp = sub.add_parser("bench", help="speed benchmarks with ratios measured in the same run")
    bp.add_argument("what", help="'gpu' (every method on a GPU against numba and OIDN, "
                    "results/gpu/<device>.json), 'kernels' (every GPU kernel variant compiled "
                    "for a CUDA target here, no GPU needed: --arch, --jobs), "
                    "'render' (statistics cost), 'metrics' (the judge against "
                    "the plain metrics), 'video-metrics' (ColorVideoVDP against the "
                    "per-frame and temporal metrics on a sequence), 'scene-file' (an XML scene against the catalogue's), "
                    "'plugins' (entry-point discovery time) or a method name")
    bp.add_argument("--scene", default=None, help="render: the scene rendered (default "
                    "cornell; a transient scene times its per-bin statistics)")
    bp.add_argument("--res", default=None, help="image size: N (N×N) or WIDTHxHEIGHT, "
                    "e.g. 1280x720 (render: default 256; methods, metrics: default --width "
                    "× --height)")
    bp.add_argument("--spp", type=count, default=None, help="samples per pixel: of the render "
                    "(render, scene-file: default 64) or of the synthetic frame's statistics "
                    "a method is timed on (default 16; a method whose settings follow the spp, "
                    "like nca's steps, takes them from it)")
    bp.add_argument("--bins", type=count, default=None, help="render on a transient scene: "
                    "time bins (default 100; the window stays the scene's)")
    bp.add_argument("--param", action="append", metavar="KEY=VALUE",
                    help="a parameter of the method timed (repeatable)")
    bp.add_argument("--height", type=integer, default=None, help="methods, metrics, "
                    "video-metrics, gpu: image height (default 720; not with --res)")
    bp.add_argument("--width", type=integer, default=None, help="methods, metrics, "
                    "video-metrics, gpu: image width (default 1280; not with --res)")
    bp.add_argument("--repeats", type=count, default=None, help="timed rounds (default 3)")
    bp.add_argument("--arch", type=count, default=None, help="kernels: the CUDA compute "
                    "capability to compile for, e.g. 90 (default: the GPU here, else 90)")
    bp.add_argument("--jobs", type=count, default=None, help="kernels, gpu: compilations run "
                    "side by side (default: one per core)")
    _device_argument(bp, None)
    bp.add_argument("--out", default=None, help="append the result to this JSON-lines file")
    bp.set_defaults(func=cmd_bench)

    tp = sub.add_parser("train", help="train nca or autoencoder on procedural training scenes "
                        "rendered here; writes <name>.onnx and <name>.json")
    tp.add_argument("method", choices=["nca", "autoencoder"], help="the model trained")
    # the defaults of --steps and --width-scale are NCAConfig's and AEConfig's
    # (dbench/learn/configs.py; tests/cli/test_help_texts.py holds them equal)
    tp.add_argument("--steps", type=integer, default=None, help="optimiser steps, >= 1 "
                    "(default: nca 2000, autoencoder 6000; the autoencoder's stage 1)")
    tp.add_argument("--minutes", type=number, default=None, help="stop after this many "
                    "minutes of wall time, > 0 (default: no limit; the autoencoder's stage 1)")
    tp.add_argument("--scenes", type=integer, default=48,
                    help="training scenes (nca holds 4 out, autoencoder 2; at least one more)")
    tp.add_argument("--res", type=integer, default=128, help="side of the square training "
                    "images, at least the crops trained on: nca 64, autoencoder 96 "
                    "(default 128)")
    tp.add_argument("--width-scale", type=number, default=None, help="autoencoder: factor "
                    "on its encoder and decoder widths (channels), > 0 (default 0.5)")
    tp.add_argument("--sequences", type=integer, default=None,
                    help="autoencoder: training sequences for the recurrent stage, 2 held out "
                    "(default 16; 0: single frames only)")
    tp.add_argument("--from-weights", default=None, metavar="ONNX",
                    help="autoencoder: start from these weights (their .json beside them) and "
                    "run only the consistency stage (stage 3)")
    tp.add_argument("--out", default=None, help="output folder (default: the method's package "
                    "folder, replacing the shipped weights)")
    common(tp, train=True)
    tp.set_defaults(func=cmd_train)
    for sp in sub.choices.values():
        # counts checked first; no sys.exit of a plugin ends the command (dbench.cli.guard)
        sp.set_defaults(func=command(sp.get_default("func")))
    for sp in sub.choices.values():  # taken out of argv by main() wherever it stands; shown here
        sp.add_argument("--plugin", action="append", metavar="MODULE_OR_FILE.py",
                        help=PLUGIN_HELP)
    return p


def _normal_encoding_argument(p: argparse.ArgumentParser,
                              what: str = "a folder of renders") -> None:
    p.add_argument("--normal-encoding", type=normal_encoding_arg, default=None,
                   metavar="{signed,unsigned}", help=f"{what}: how the normal images are "
                   "stored, n in [-1, 1] (signed) or n*0.5+0.5 (unsigned); wins over "
                   "dataset.json's normal_encoding and over the detection (README.md, "
                   "\"Renders from another renderer\")")


def _device_argument(parser, default: str | None = "auto") -> None:
    """``--device``; bench's default is None (auto), so that a benchmark that runs on the CPU
    alone can refuse it given (dbench.cli.bench.READS)."""
    parser.add_argument("--device", default=default, help="where methods with a GPU path run "
                        "and where Mitsuba renders: cpu, cuda, or auto (default: cuda when "
                        "PyTorch sees a usable GPU, rendering on cuda_ad_rgb where its probe "
                        "passes); methods without one run on the CPU and say so (docs/gpu.md)"
                        + ("" if default else "; bench: render, scene-file, gpu and methods "
                           "only"))
