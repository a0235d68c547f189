"""Speed benchmarks that print ratios measured in the same run.

* ``bench_render``: statistics collection (individual samples + float64 power sums) against one
  plain render of the same spp, and the samples without statistics; on JIT variants also the
  host path the one-pass kernel replaced, in the same interleaved rounds.
* ``bench_method``: a method on a synthetic frame of a given size, against OIDN in the same run;
  a module of :mod:`dbench.speed` named after the method adds its
  fast-path-versus-reference figures (``benchmark()``).
* ``bench_metrics``: the judge (whole-image and surface metrics, top1_share, unbiased figures,
  and with one seed the block bootstrap) against the plain metrics it replaces
  (``metrics.compute_all`` of rmse, relmse, smape, psnr, ssim, flip) on the same image.
"""
from __future__ import annotations

import importlib
import inspect
import json
import statistics
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ..memory import advice_text
from ..run import fpenv
from ..run.machine import machine_info
from ..resolution import parse_res, size_text


def median_time(fn: Callable[[], Any], repeats: int) -> float:
    """Median wall seconds of ``repeats`` calls of ``fn()`` after one warm-up call."""
    fn()  # warm-up: JIT compilation and scene loading are not part of the figure
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def interleaved_times(fns: list[Callable[[], Any]], repeats: int) -> list[list[float]]:
    """Wall seconds of each of ``fns`` in each of ``repeats`` rounds (after one warm-up round),
    each round calling them one after another, the order reversed every other round (ABBA), so
    that a slow spell of the machine falls on all of them alike and none always runs first:
    the ratio of two functions' times in the same round is far steadier than with the functions
    timed one block after the other (a gate's share of 41-72 % in separate blocks)."""
    for fn in fns:
        fn()
    times: list[list[float]] = [[] for _ in fns]
    order = list(range(len(fns)))
    for r in range(repeats):
        for k in (order if r % 2 == 0 else order[::-1]):
            t0 = time.perf_counter()
            fns[k]()
            times[k].append(time.perf_counter() - t0)
    return times


#: what a fresh process runs (:func:`first_call_times`): ``target`` ("module:function") builds
#: the call of ``way`` from the keyword arguments, untimed; only the call itself is timed
_FIRST_CALL_CHILD = (
    "import importlib, json, sys, time\n"
    "module, name = sys.argv[1].split(':')\n"
    "call = getattr(importlib.import_module(module), name)(sys.argv[2], **json.loads(sys.argv[3]))\n"
    "t0 = time.perf_counter()\n"
    "call()\n"
    "print(json.dumps(time.perf_counter() - t0))\n")


def first_call_times(target: str, ways: list[str], kwargs: dict[str, Any], rounds: int,
                     env: dict[str, str] | None = None) -> dict[str, list[float]]:
    """Wall seconds of the first call of each of ``ways`` in a fresh Python process, ``rounds``
    processes each, the order reversed every other round (as :func:`interleaved_times`).
    What the warm rounds leave out and a one-off ``dbench run`` pays: the first trace of each
    kernel in a process, memory touched for the first time, code loaded on first use. Imports
    and building the call are not timed; compiled kernels come from the disk caches the warm
    rounds filled. ``target(way, **kwargs)`` returns the call (its module's docstring says
    what each way is); ``env`` is added to this process's environment."""
    import os
    import subprocess
    import sys

    times: dict[str, list[float]] = {w: [] for w in ways}
    for r in range(rounds):
        for way in (ways if r % 2 == 0 else ways[::-1]):
            done = subprocess.run(
                [sys.executable, "-c", _FIRST_CALL_CHILD, target, way, json.dumps(kwargs)],
                capture_output=True, text=True, env={**os.environ, **(env or {})})
            lines = done.stdout.strip().splitlines()
            if done.returncode != 0 or not lines:
                said = (done.stderr.strip().splitlines() or ["no output"])[-1]
                raise RuntimeError(f"first call of {way!r} in a fresh process failed "
                                   f"(exit {done.returncode}): {said}")
            times[way].append(float(json.loads(lines[-1])))
    return times


def round_medians(times: dict[str, list[float]], ratios: dict[str, str],
                  base: str = "plain") -> dict[str, Any]:
    """``<name>_s``: the median of each timing's rounds (:func:`interleaved_times`), and for each
    name in ``ratios`` the median of its per-round ratio to ``base`` under ``ratios[name]``;
    the machine and the time of day."""
    out: dict[str, Any] = {}
    for name, t in times.items():
        out[f"{name}_s"] = statistics.median(t)
        if name in ratios:
            out[ratios[name]] = statistics.median(np.array(t) / np.array(times[base]))
    out.update(machine=machine_info()["cpu"], when=time.strftime("%Y-%m-%d %H:%M:%S"))
    return out


def reference_crop(height: int, width: int, max_pixels: int) -> tuple[int, int]:
    """The (height, width) of the crop a slow reference is timed on: the frame halved until it
    holds at most ``max_pixels`` pixels (its time is then scaled by the pixel count: a reference
    costs the same per pixel)."""
    ch, cw = height, width
    while ch * cw > max_pixels:
        ch, cw = max(1, ch // 2), max(1, cw // 2)
    return ch, cw


def paired_share(times_a: list[float], times_b: list[float]) -> dict[str, float]:
    """What A adds to B, from their times in the same rounds (:func:`interleaved_times`): the
    median of the per-round ratios A/B − 1, with their quartiles as its spread."""
    shares = np.array(times_a) / np.array(times_b) - 1.0
    q25, q50, q75 = np.percentile(shares, [25, 50, 75])
    return {"median": float(q50), "q25": float(q25), "q75": float(q75), "rounds": len(shares)}


#: The ratio to the plain render that each timed way of rendering the samples is reported as.
_RENDER_RATIOS = {"samples": "ratio_samples_vs_plain", "samples_stats": "ratio_stats_vs_plain",
                  "host_samples": "ratio_host_samples_vs_plain",
                  "host_samples_stats": "ratio_host_stats_vs_plain"}


def bench_render(scene: str = "cornell", res=256, spp: int = 64, repeats: int = 3,
                 transform: str = "box-cox", lam: float = 0.5) -> dict[str, Any]:
    """Statistics cost against one plain ``spp``-spp render, same run: the samples with and
    without statistics on the path dbench renders with (the one-pass kernel on JIT variants,
    :mod:`dbench.datasets.render_moments`) and, on JIT variants, on the host path it replaced
    (``batch`` sensor films to NumPy + compiled power sums). All are timed in interleaved rounds
    (:func:`interleaved_times`); the ratios are medians of the per-round ratios to the plain
    render, so a slow spell of a shared machine falls on both sides of each ratio."""
    from ..datasets import render
    from ..datasets.scenes import catalogue as scenes
    from ..datasets.mitsuba_env import mitsuba

    sc = scenes.get(scene)
    variant = mitsuba().variant()
    kernel = render.jit_variant(variant)
    st = (transform, lam)
    fns = {"plain": lambda: render.render_plain(sc, res, spp),
           "samples": lambda: render.render_passes(sc, res, spp, progress=False),
           "samples_stats": lambda: render.render_passes(sc, res, spp, stats=st,
                                                         progress=False)}
    if kernel:
        fns["host_samples"] = lambda: render.render_passes(sc, res, spp, progress=False,
                                                           kernel=False)
        fns["host_samples_stats"] = lambda: render.render_passes(sc, res, spp, stats=st,
                                                                 progress=False, kernel=False)
    times = dict(zip(fns, interleaved_times(list(fns.values()), repeats)))
    out: dict[str, Any] = {"benchmark": "render", "scene": scene, "res": parse_res(res).key,
                           "spp": spp, "copies_per_call": render.batch_size(res, spp),
                           "transform": transform, "variant": variant, "rounds": repeats,
                           "path": "kernel" if kernel else "host", "memory": advice_text()}
    out.update(round_medians(times, _RENDER_RATIOS))
    return out


#: Samples per pixel of the synthetic frame a method is timed on (``dbench bench METHOD``).
METHOD_SPP = 16
#: Rounds at least of ``NAME+gate`` and ``NAME`` timed in turn for the gate's share.
GATE_SHARE_ROUNDS = 15


@contextmanager
def method_failure(name: str):
    """A method's exception (or ``sys.exit``) inside the block as a
    :class:`~dbench.run.inputs.MethodError` naming it, in one line (``dbench bench`` exits 4:
    a method failed, README.md "Add your own denoiser"); dbench's own refusals of bad input
    (DbenchInputError) pass unchanged."""
    from ..errors import DbenchInputError
    from ..run.inputs import MethodError, input_guard, method_failure as failure_text

    try:
        with input_guard(name):
            yield
    except (DbenchInputError, MethodError):
        raise
    except (Exception, SystemExit) as exc:  # noqa: BLE001 - the method's failure, named
        raise MethodError(f"{name} failed: {failure_text(exc)}") from exc


def check_output(name: str, output: Any, shape: tuple) -> None:
    """Refuse an output that is not an array of real numbers of ``shape`` (the input colour's)
    as ``dbench run`` refuses it (:func:`dbench.run.inputs.check_output`), as the method's
    failure (MethodError: ``dbench bench`` exits 4), not as bad input of the user's."""
    from ..errors import DbenchInputError
    from ..run.inputs import MethodError, check_output as checked

    try:
        checked(name, output, shape)
    except DbenchInputError as exc:
        raise MethodError(str(exc)) from exc


def bench_method(name: str, height: int = 720, width: int = 1280, repeats: int = 3,
                 spp: int = METHOD_SPP, params: dict[str, Any] | None = None
                 ) -> dict[str, Any]:
    """A method's time per frame on a synthetic (height, width) frame whose statistics are of
    ``spp`` samples (a method whose settings follow the spp, like ``nca``'s step count, takes
    them from it), built with ``params``; OIDN timed in the same run. On a GPU:
    :func:`dbench.speed.gpu.bench_method_device`."""
    from .. import registry
    from ..run.inputs import check_unchanged, private_copy
    from ..synthetic import base_frame

    # the frame says its spp as a rendered frame does (meta), for methods that follow it
    frame = base_frame(height, width, spp=spp).with_buffers(meta={"spp": spp})
    method = registry.get(name, **(params or {}))
    if not {"steady", "sequence"} & set(method.kinds):
        from ..errors import DbenchInputError
        raise DbenchInputError(f"bench {name}: a method is timed on a steady frame (or a "
                               f"sequence's frames); {name} works on {sorted(method.kinds)}")
    if "steady" not in method.kinds and "sequence" in method.kinds:
        # A temporal method is timed per frame in steady state: zero motion (static camera) and
        # an unchanged-light gradient frame, so every call reprojects history, after the
        # warm-up frames (SVGF estimates variance spatially, 2x slower, while history < 4).
        from ..run.sequence_run import WARMUP

        frame = frame.with_buffers(motion=np.zeros((height, width, 2), np.float32),
                                   gradient=np.array(frame.color, copy=True))
    # the method's own read-only copy, as the harness gives it (dbench/run/inputs.py): a
    # method writing to its input would otherwise time later calls, and OIDN, on other data
    mine = private_copy(frame)
    steady = "steady" in method.kinds

    def run(m):
        # a steady frame is denoised as the harness does it, with the method's state reset
        # (a recurrent model would otherwise run its stateful graph on every call after the
        # first); temporal methods keep their history
        if steady:
            m.reset()
        return fpenv.denoise(m, mine)

    with method_failure(name):
        if not steady:
            method.reset()
            for _ in range(WARMUP):
                fpenv.denoise(method, mine)
        check_output(name, run(method), frame.color.shape)  # a time of no output is no time
        wrapped = getattr(type(method), "wrapped", None)
        if wrapped is not None:  # NAME+gate: the method alone, interleaved with it: its share
            inner = method.inner
            rounds = interleaved_times([lambda: run(method), lambda: run(inner)],
                                       max(repeats, GATE_SHARE_ROUNDS))
            t_method, t_inner = (statistics.median(t) for t in rounds)
            share = paired_share(*rounds)
        else:
            t_method = median_time(lambda: run(method), repeats)
    check_unchanged(name, mine, frame)
    oidn = registry.get("oidn")
    t_oidn = median_time(lambda: fpenv.denoise(oidn, frame), repeats)
    result: dict[str, Any] = {"benchmark": "method", "method": name, "height": height,
                              "width": width, "spp": spp, "params": method.params,
                              "settings": dict(getattr(method, "last_settings", {}) or {}),
                              "time_s": t_method,
                              "oidn_time_s": t_oidn, "ratio_vs_oidn": t_method / t_oidn,
                              "mpix_per_s": height * width / t_method / 1e6,
                              "machine": machine_info()["cpu"],
                              "when": time.strftime("%Y-%m-%d %H:%M:%S")}
    if wrapped is not None:
        result.update({"wrapped": wrapped.name, "wrapped_time_s": t_inner,
                       "gate_overhead": share["median"],
                       "gate_overhead_quartiles": [share["q25"], share["q75"]],
                       "gate_overhead_rounds": share["rounds"]})
    try:
        extra = importlib.import_module(f"dbench.speed.{name}")
    except ModuleNotFoundError:
        extra = None
    if extra is not None and hasattr(extra, "benchmark"):
        takes_spp = "spp" in inspect.signature(extra.benchmark).parameters
        result["fast_vs_reference"] = extra.benchmark(height=height, width=width,
                                                      repeats=repeats,
                                                      **({"spp": spp} if takes_spp else {}))
    return result


def bench_metrics(height: int = 256, width: int = 256, repeats: int = 5) -> dict[str, Any]:
    """Metric time of one output, old (plain metrics) against new (the judge), same run."""
    from .. import metrics
    from ..metrics import judge

    rng = np.random.default_rng(0)
    ref = rng.gamma(2.0, 0.3, (height, width, 3))
    out = ref + rng.normal(0.0, 0.05, ref.shape)
    emitter = np.zeros((height, width, 1))
    emitter[: height // 8, : width // 8] = 1.0
    var = np.full(ref.shape, 1e-4)
    names = list(judge.JUDGED)
    plain = median_time(lambda: metrics.compute_all(out, ref, names=names), repeats)
    judged = median_time(lambda: judge.judge(out, ref, emitter=emitter, reference_var=var),
                         repeats)
    j = judge.judge(out, ref, emitter=emitter, reference_var=var)
    boot = median_time(lambda: judge.bootstrap_interval([j], judge.metric_names()), repeats)
    return {"benchmark": "metrics", "height": height, "width": width, "plain_s": plain,
            "judge_s": judged, "bootstrap_s": boot,
            "ratio_judge_vs_plain": judged / plain,
            "ratio_judge_bootstrap_vs_plain": (judged + boot) / plain,
            "machine": machine_info()["cpu"], "when": time.strftime("%Y-%m-%d %H:%M:%S")}


def format_result(result: dict[str, Any]) -> str:
    if result["benchmark"] == "metrics":
        return (f"metric benchmark at {result['width']}x{result['height']}:\n"
                f"  plain metrics (6)            {result['plain_s'] * 1e3:.1f} ms\n"
                f"  judge (+ surface, top1, unbiased) {result['judge_s'] * 1e3:.1f} ms "
                f"({result['ratio_judge_vs_plain']:.2f}x plain)\n"
                f"  judge + one-seed bootstrap   {(result['judge_s'] + result['bootstrap_s']) * 1e3:.1f} ms "
                f"({result['ratio_judge_bootstrap_vs_plain']:.2f}x plain)")
    if result["benchmark"] == "render":
        lines = [f"render benchmark: {result['scene']} {size_text(result['res'])} at "
                 f"{result['spp']} spp, {result.get('variant', '?')} "
                 f"({result['copies_per_call']} samples per pixel per batch; ratios: medians "
                 f"over {result.get('rounds', '?')} interleaved rounds)",
                 f"  plain render           {result['plain_s']:.3f} s",
                 f"  samples, no statistics {result['samples_s']:.3f} s "
                 f"({result['ratio_samples_vs_plain']:.2f}x plain)",
                 f"  samples + statistics   {result['samples_stats_s']:.3f} s "
                 f"({result['ratio_stats_vs_plain']:.2f}x plain)"]
        if "host_samples_s" in result:
            lines += [f"  host path, no statistics {result['host_samples_s']:.3f} s "
                      f"({result['ratio_host_samples_vs_plain']:.2f}x plain)",
                      f"  host path + statistics   {result['host_samples_stats_s']:.3f} s "
                      f"({result['ratio_host_stats_vs_plain']:.2f}x plain)"]
        return "\n".join(lines)
    where = (f" on {result['machine']}, {result['backend']}" if result.get("device") else "")
    lines = [f"{result['method']}{where} at {result['width']}x{result['height']}"
             f"{', %s spp' % result['spp'] if 'spp' in result else ''}: "
             f"{result['time_s'] * 1e3:.1f} ms ({result['mpix_per_s']:.2f} Mpix/s); "
             f"oidn {result['oidn_time_s'] * 1e3:.1f} ms; ratio {result['ratio_vs_oidn']:.2f}x oidn"]
    if "wrapped" in result:
        lines.append(f"  {result['wrapped']} alone {result['wrapped_time_s'] * 1e3:.1f} ms in the "
                     f"same run: the gate adds {result['gate_overhead']:.1%} (median of "
                     f"{result['gate_overhead_rounds']} paired rounds; quartiles "
                     f"{result['gate_overhead_quartiles'][0]:.1%} to "
                     f"{result['gate_overhead_quartiles'][1]:.1%})")
    if "fast_vs_reference" in result:
        lines.append(f"  fast path vs reference: {json.dumps(result['fast_vs_reference'], default=str)}")
    return "\n".join(lines)


def append_result(path: str | Path, result: dict[str, Any]) -> None:
    """Append one JSON line to ``path`` (rewritten atomically so a crash never truncates it)."""
    from ..io import write_text

    path = Path(path)
    old = path.read_text(encoding="utf-8") if path.exists() else ""
    write_text(path, old + json.dumps(result, default=str) + "\n")
