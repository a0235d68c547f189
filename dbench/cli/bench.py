"""``dbench bench``: speed benchmarks with ratios measured in the same run (dbench/speed).

Each benchmark reads some of the options (:data:`READS`); one it does not read is refused in
one line naming it and the benchmark (exit 2, README.md "Usage"), never ignored, and so are
``--res`` given with ``--width``/``--height`` (one size, two ways) and a ``--device`` that
``run`` would refuse (:func:`dbench.device.resolve_device`).
"""
from __future__ import annotations

import argparse
import sys

from ..errors import DbenchInputError
from .args import parse_params

#: The options each benchmark reads besides ``--out`` (every one appends its record there);
#: ``method`` stands for ``dbench bench METHOD``. ``--device`` is where Mitsuba renders for
#: render and scene-file, where the method runs for a method; metrics, video-metrics, plugins
#: and kernels run on the CPU alone.
READS = {
    "render": ("scene", "res", "spp", "bins", "repeats", "device"),
    "scene-file": ("res", "spp", "repeats", "device"),
    "plugins": ("repeats",),
    "metrics": ("res", "width", "height", "repeats"),
    "video-metrics": ("res", "width", "height", "repeats"),
    "gpu": ("res", "width", "height", "repeats", "jobs", "device"),
    "kernels": ("arch", "jobs"),
    "method": ("res", "width", "height", "spp", "param", "repeats", "device"),
}
#: Defaults of the options whose absence is told from their value (parser: None).
DEFAULTS = {"width": 1280, "height": 720, "repeats": 3}


def check_bench_options(args: argparse.Namespace) -> str:
    """Refuse every option ``args.what``'s benchmark does not read (:data:`READS`); the
    benchmark's key in READS."""
    kind = args.what if args.what in READS else "method"
    if kind == "method":
        from .. import registry

        registry.method_class(args.what)  # an unknown name lists the valid ones first
    if args.scene is not None and kind != "render":  # the reason, in words
        raise DbenchInputError(f"--scene: only bench render renders a scene, not {args.what!r} "
                               f"(methods and metrics are timed on synthetic frames)")
    if args.param and kind not in ("method", "gpu", "kernels"):  # the last two say why
        raise DbenchInputError(f"--param: only a method's benchmark takes parameters, not "
                               f"{args.what!r}")
    name = f"bench {args.what}" + (" (a method's benchmark)" if kind == "method" else "")
    for dest in ("res", "width", "height", "spp", "bins", "repeats", "arch", "jobs", "device"):
        if getattr(args, dest) is not None and dest not in READS[kind]:
            reads = ", ".join(f"--{d}" for d in READS[kind] + ("out",))
            raise DbenchInputError(f"--{dest}: {name} does not read it (it reads {reads}); "
                                   f"leave it out")
    if args.res is not None and (args.width is not None or args.height is not None):
        raise DbenchInputError(f"--res {args.res}: --width/--height give the size too; give "
                               f"--res or --width/--height")
    if args.device is not None and kind != "gpu":  # gpu: its own words (_bench_gpu)
        from ..device import resolve_device

        resolve_device(args.device)  # run's check: an unknown name, cuda without a GPU
    return kind


def cmd_bench(args: argparse.Namespace) -> int:
    from ..resolution import parse_res
    from ..speed import timing as speed

    kind = check_bench_options(args)
    args.scene = args.scene or "cornell"
    if args.out:  # checked before the benchmark: a refusal after it would lose its figures
        from ..io import ensure_writable_file
        ensure_writable_file(args.out, "--out")
    size_given = args.res is not None or args.width is not None or args.height is not None
    for dest, value in DEFAULTS.items():
        if getattr(args, dest) is None:
            setattr(args, dest, value)
    # --res sets the render benchmark's size (default 256) and, when given, the image size of
    # the method and metric benchmarks (instead of --width/--height)
    if args.res is None:
        parse_res((args.width, args.height), "--width/--height")
    else:
        args.res = parse_res(args.res, "--res")
        args.width, args.height = args.res
    if kind == "gpu":
        return _bench_gpu(args, size_given)
    if kind == "kernels":
        return _bench_kernels(args)
    if kind != "method":
        args.spp = 64 if args.spp is None else args.spp
    if kind == "render":
        from ..speed import transient_render as speed_transient
        if speed_transient.is_transient(args.scene):
            # transient: a plain mitransient render against dbench's load, 48² by default
            result = speed_transient.bench_render_transient(
                scene=args.scene, res=args.res or parse_res(48), spp=args.spp,
                bins=args.bins or 100, repeats=args.repeats)
            return _report(speed_transient.format_result(result), result, args.out)
        if args.bins is not None:
            raise DbenchInputError(f"--bins: only a transient scene has time bins, not "
                                   f"{args.scene!r}")
        result = speed.bench_render(scene=args.scene, res=args.res or parse_res(256),
                                    spp=args.spp, repeats=args.repeats)
    elif kind in ("scene-file", "plugins"):
        from ..speed import files as speed_files
        result = (speed_files.bench_plugin_discovery(repeats=args.repeats)
                  if kind == "plugins" else
                  speed_files.bench_scene_file(res=args.res or parse_res(256), spp=args.spp,
                                               repeats=args.repeats))
        return _report(speed_files.format_result(result), result, args.out)
    elif kind == "metrics":
        result = speed.bench_metrics(height=args.height, width=args.width,
                                     repeats=args.repeats)
    elif kind == "video-metrics":
        from ..speed import video_metrics as speed_video
        result = speed_video.bench_video_metrics(height=args.height, width=args.width,
                                                 repeats=args.repeats)
        return _report(speed_video.format_result(result), result, args.out)
    else:
        params = parse_params(args.param or [], [args.what]).get(args.what, {})
        from ..device import resolve_device
        device = resolve_device(args.device or "auto")
        spp = speed.METHOD_SPP if args.spp is None else args.spp
        if device != "cpu":
            from ..speed.gpu import bench_method_device
            result = bench_method_device(args.what, args.height, args.width, args.repeats, spp,
                                         params, device)
        else:
            from ..run.inputs import MethodError
            try:
                result = speed.bench_method(args.what, height=args.height, width=args.width,
                                            repeats=args.repeats, spp=spp, params=params)
            except MethodError as exc:  # the method failed: no time, nothing appended to --out
                print(f"dbench: bench {exc}", file=sys.stderr)
                return 4
    return _report(speed.format_result(result), result, args.out)


def _report(text: str, result: dict, out: str | None) -> int:
    """Print a benchmark's ``text``; append its ``result`` to ``out`` when given."""
    from ..speed import timing as speed

    print(text)
    if out:
        speed.append_result(out, result)
    return 0


def _bench_kernels(args: argparse.Namespace) -> int:
    """``dbench bench kernels``: every Triton kernel variant compiled for a CUDA target, here
    (dbench.speed.kernels; no GPU needed)."""
    from ..speed import kernels

    if args.param:
        raise DbenchInputError("--param: bench kernels compiles every method with its defaults")
    result = kernels.precompile(arch=args.arch, jobs=args.jobs, log=print)
    _report(kernels.format_result(result), result, args.out)
    return 1 if result["errors"] else 0


def _bench_gpu(args: argparse.Namespace, size_given: bool) -> int:
    """``dbench bench gpu``: results/gpu/<device>.json and its table (dbench.speed.gpu).
    ``size_given``: --res or --width/--height given (a dry run on the CPU is 24 × 16 without)."""
    from ..device import resolve_device
    from ..speed import gpu

    device_name = args.device or "auto"
    if device_name == "auto" and resolve_device("auto") != "cuda":
        raise DbenchInputError("bench gpu: PyTorch sees no usable CUDA GPU here; run it on a GPU "
                               "machine, or pass --device cpu for a dry run on small frames")
    device = resolve_device(device_name)
    if args.param:
        raise DbenchInputError("--param: bench gpu times every method with its defaults")
    if device == "cpu" and args.jobs is not None:
        raise DbenchInputError("--jobs: bench gpu compiles kernels only on cuda; the dry run "
                               "on the CPU compiles none")
    if device == "cpu" and not size_given:
        args.width, args.height = 24, 16  # a dry run: the kernels through the interpreter
    pre = None
    if device == "cuda":  # every kernel compiled side by side first (docs/gpu.md §6)
        from ..speed.kernels import precompile
        # at the sizes timed below: Triton's variants depend on them (dbench/speed/kernels.py)
        pre = precompile(jobs=args.jobs, log=print,
                         sizes=[(args.height, args.width), gpu.HOSTILE_SIZE],
                         transient_size=gpu.TRANSIENT_SIZE)
        print(f"compiled {pre['variants']} kernel variants in {pre['compile_wall_s']:.1f} s "
              f"({pre['jobs']} at a time, {pre['errors']} failed)")
    # a dry run times the transient renders at 8² (the same code, seconds)
    renders = gpu.TRANSIENT_RENDERS if device == "cuda" or args.res is not None else \
        tuple((scene, 8, target) for scene, _, target in gpu.TRANSIENT_RENDERS)
    result = gpu.bench_gpu(height=args.height, width=args.width, device=device,
                           repeats=max(args.repeats, 1), precompiled=pre,
                           transient_renders=renders)
    print(gpu.markdown(result))
    if device == "cuda" or args.out:
        path = args.out or gpu.result_path(result)
        gpu.write_result(result, path)
        print(f"\nwritten: {path}")
    return 0


__all__ = ["READS", "check_bench_options", "cmd_bench"]
