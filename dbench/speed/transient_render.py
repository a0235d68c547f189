"""``dbench bench render`` on a transient scene: per-bin statistics against a plain mitransient
render, in the same interleaved rounds (:func:`dbench.speed.timing.interleaved_times`).

Timed, each of ``spp`` samples per pixel at the same size and bins (README.md, "How renders
work"; docs/architecture.md):

* ``plain``: one ``mi.render`` of the scene's transient dictionary (its ``transient_hdr_film``
  and the scene's own integrator, ``transient_path`` or ``transient_prbvolpath``), the streak
  film and steady image brought to NumPy (:func:`dbench.datasets.transient.render.render_signal`):
  what mitransient alone costs, with no statistics.
* ``color``: the colour alone through :func:`dbench.datasets.transient.load.load_transient`
  (``needs={"color"}``) into a fresh, empty cache, as a user waits for it.
* ``color_stats``: colour and per-bin statistics through the same call, fresh cache.
* ``color_stats_nocache``: the same with the cache off (rendering and collecting only), which
  separates what the collector costs from what storing its arrays costs.
* ``color_stats_cached``: the same from a cache that holds them (a second run): reading,
  checking and unpacking the entries, against rendering them again.

The ratios are medians of the per-round ratios to ``plain``. After the warm rounds, ``plain``
and ``color_stats`` are timed once more each as the first call of a fresh process
(:func:`dbench.speed.timing.first_call_times`, :func:`first_call`): what a one-off ``dbench
run`` waits for, beside the warm figures of a long sweep.
"""
from __future__ import annotations

import shutil
import tempfile
from pathlib import Path
from typing import Any


from .timing import first_call_times, interleaved_times, round_medians
from ..memory import advice_text
from ..resolution import parse_res, size_text

#: what each timed way is reported as, against the plain mitransient render
RATIOS = {"color": "ratio_color_vs_plain", "color_stats": "ratio_stats_vs_plain",
          "color_stats_nocache": "ratio_stats_nocache_vs_plain",
          "color_stats_cached": "ratio_stats_cached_vs_plain"}
#: fresh processes per way, at most, for the first-call figures (each imports Mitsuba: seconds)
FIRST_ROUNDS = 3


def first_call(way: str, scene: str, res: int | str, spp: int, bins: int, transform: str,
               lam: float, cache_root: str):
    """The call a fresh process times for :func:`bench_render_transient`'s first-call figures:
    ``"plain"`` renders as mitransient alone, ``"color_stats"`` loads colour and statistics
    into a new empty cache folder under ``cache_root``. The catalogue scene is looked up here,
    untimed; loading it into Mitsuba is part of either call."""
    from ..datasets.cache import Cache
    from ..datasets.scenes import catalogue as scenes
    from ..datasets.transient import load as tr
    from ..datasets.transient.render import render_signal

    sc = scenes.get(scene)
    window = sc.window(bins)
    tr._mitransient()
    if way == "plain":
        return lambda: render_signal(sc, parse_res(res), window, 1, spp, 0)
    cache = Cache(Path(tempfile.mkdtemp(dir=cache_root)))
    return lambda: tr.load_transient(sc, spp, parse_res(res), needs={"color", "stats"},
                                     transform=transform, lam=lam, bins=window.bins,
                                     cache=cache, progress=False)


def is_transient(scene: str) -> bool:
    """Whether the catalogue scene ``scene`` is a transient one (``dbench bench render``
    then times :func:`bench_render_transient`)."""
    from ..datasets.scenes import catalogue as scenes
    from ..datasets.transient.scene import TransientScene

    return isinstance(scenes.get(scene), TransientScene)


def bench_render_transient(scene: str = "fog-transient", res=48, spp: int = 64,
                           bins: int | None = 100, repeats: int = 3,
                           transform: str = "identity", lam: float = 0.5,
                           first_rounds: int = FIRST_ROUNDS) -> dict[str, Any]:
    """Per-bin statistics cost of the transient scene ``scene`` against a plain mitransient
    render of the same spp, size and bins, all timed in interleaved rounds after one warm-up
    round (JIT compilation and scene loading are not part of the figures), then the first call
    of a fresh process, ``min(repeats, first_rounds)`` processes each (0: none)."""
    from ..datasets.scenes import catalogue as scenes
    from ..datasets.transient import load as tr
    from ..datasets.cache import Cache
    from ..datasets.mitsuba_env import mitsuba
    from ..datasets.transient.render import render_signal

    sc = scenes.get(scene)
    res = parse_res(res)
    window = sc.window(bins)
    tr._mitransient()
    variant = mitsuba().variant()
    root = Path(tempfile.mkdtemp(prefix="dbench-bench-transient-"))
    calls = [0]

    def fresh_cache() -> Cache:
        # a new empty folder per call: every call renders and stores, as on a first run
        calls[0] += 1
        return Cache(root / f"c{calls[0]}")

    def load(needs: set[str], cache: Cache):
        return tr.load_transient(sc, spp, res, needs=needs, transform=transform, lam=lam,
                                 bins=window.bins, cache=cache, progress=False)

    filled = Cache(root / "filled")
    load({"color", "stats"}, filled)
    fns = {"plain": lambda: render_signal(sc, res, window, 1, spp, 0),
           "color": lambda: load({"color"}, fresh_cache()),
           "color_stats": lambda: load({"color", "stats"}, fresh_cache()),
           "color_stats_nocache": lambda: load({"color", "stats"}, Cache(enabled=False)),
           "color_stats_cached": lambda: load({"color", "stats"}, filled)}
    try:
        times = dict(zip(fns, interleaved_times(list(fns.values()), repeats)))
        frame = load({"color", "stats"}, Cache(enabled=False))
        # what the cached way read (both entries, or it timed a render)
        hits = list(load({"color", "stats"}, filled).meta["cache_hits"])
        first = first_call_times(
            f"{__name__}:first_call", ["plain", "color_stats"],
            dict(scene=scene, res=res.key, spp=int(spp), bins=window.bins,
                 transform=transform, lam=float(lam), cache_root=str(root)),
            min(repeats, first_rounds), env={"DBENCH_VARIANT": variant})
    finally:
        shutil.rmtree(root, ignore_errors=True)
    out: dict[str, Any] = {"benchmark": "render-transient", "scene": scene, "res": res.key,
                           "spp": int(spp), "bins": window.bins,
                           "integrator": sc.integrator, "collector": frame.meta["collector"],
                           "sums_layout": frame.meta.get("sums_layout"),
                           "transform": transform, "variant": variant, "rounds": repeats,
                           "cached_hits": hits, "memory": advice_text()}
    out.update(round_medians(times, RATIOS))
    if first["plain"]:
        out.update(round_medians({f"first_{k}": t for k, t in first.items()},
                                 {"first_color_stats": "ratio_first_stats_vs_plain"},
                                 base="first_plain"), first_rounds=len(first["plain"]))
    return out


def format_result(result: dict[str, Any]) -> str:
    r = result
    return "\n".join([
        f"transient render benchmark: {r['scene']} {size_text(r['res'])} × {r['bins']} bins at "
        f"{r['spp']} spp, {r['integrator']}, collector {r['collector']}"
        + (f" ({r['sums_layout']} layout)" if r.get("sums_layout") else "")
        + f", {r['variant']} "
        f"(ratios: medians over {r['rounds']} interleaved rounds)",
        f"  plain mitransient render         {r['plain_s']:.3f} s",
        f"  colour (load, fresh cache)       {r['color_s']:.3f} s "
        f"({r['ratio_color_vs_plain']:.2f}x plain)",
        f"  colour + statistics (load)       {r['color_stats_s']:.3f} s "
        f"({r['ratio_stats_vs_plain']:.2f}x plain)",
        f"  colour + statistics, no cache    {r['color_stats_nocache_s']:.3f} s "
        f"({r['ratio_stats_nocache_vs_plain']:.2f}x plain)"]
        + ([f"  colour + statistics, cached      {r['color_stats_cached_s']:.3f} s "
            f"({r['ratio_stats_cached_vs_plain']:.2f}x plain)"]
           if "color_stats_cached_s" in r else [])
        + ([f"  first call in a fresh process ({r['first_rounds']} each): plain "
            f"{r['first_plain_s']:.3f} s, colour + statistics (load) "
            f"{r['first_color_stats_s']:.3f} s ({r['ratio_first_stats_vs_plain']:.2f}x plain)"]
           if "first_plain_s" in r else []))
