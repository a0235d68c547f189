"""The transient statistics collectors' cost (results/transient.md): collector (a) (1-spp passes
+ host power sums) and collector (b) (in-integrator running sums: ``transient_path_stats``, or
``transient_prbvolpath_stats`` for participating media) as ratios to one plain render of the
scene's integrator at the same spp, measured in the same run, interleaved (median of
``repeats`` after a warm-up) (:func:`bench_collectors`); the state of collector (b) for several
spp (:func:`state_bytes_vs_spp`)."""
from __future__ import annotations

import os
import statistics
import time
from typing import Any, Sequence


def bench_collectors(scene: str = "cornell-transient", res: int = 64, spp: int = 64,
                     bins: int = 200, repeats: int = 3, transform: str = "identity",
                     lam: float = 0.5, seed: int = 0) -> dict[str, Any]:
    """Time a plain transient render (the scene's integrator), collector (a) and collector (b)
    at the same spp, interleaved.

    Returns seconds (medians) and ratios to the plain render: ``a_s`` (passes through a batch
    sensor + host sums), ``b_s`` (one in-integrator render incl. reading the sums back and the
    moments), ``b_render_s`` (the render alone), plus (b)'s state size and diagnostics.
    """
    import drjit as dr

    from ..datasets.scenes import catalogue as scenes
    from ..datasets.transient import load as tr

    sc = scenes.get(scene)
    stats = (transform, lam)
    timings: dict[str, list[float]] = {"plain": [], "a": [], "a_render": [], "b": [],
                                       "b_render": []}
    last_b = None

    def run_b():
        out = tr.collect_in_integrator(sc, res, spp, seed, bins, transform, lam)
        dr.sync_thread()
        return out

    # warm-up (kernel compilation, scene loading)
    tr.render_plain(sc, res, spp, seed, bins)
    tr.collect_passes(sc, res, spp, seed, bins, stats)
    run_b()
    for _ in range(max(1, repeats)):
        t0 = time.perf_counter()
        tr.render_plain(sc, res, spp, seed, bins)
        timings["plain"].append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        out_a = tr.collect_passes(sc, res, spp, seed, bins, stats)
        timings["a"].append(time.perf_counter() - t0)
        timings["a_render"].append(out_a.timing["render_s"])
        t0 = time.perf_counter()
        last_b = run_b()
        timings["b"].append(time.perf_counter() - t0)
        timings["b_render"].append(last_b.timing["render_s"])
    med = {k: statistics.median(v) for k, v in timings.items()}
    window = sc.window(bins)
    return {"benchmark": "transient-collectors", "scene": scene, "integrator": sc.integrator,
            "load": os.getloadavg()[0], "res": res, "spp": spp,
            "bins": window.bins, "transform": transform, "copies_a": out_a.timing["copies"],
            "plain_s": med["plain"], "a_s": med["a"], "a_render_s": med["a_render"],
            "b_s": med["b"], "b_render_s": med["b_render"], "ratio_a": med["a"] / med["plain"],
            "ratio_b": med["b"] / med["plain"], "ratio_b_render": med["b_render"] / med["plain"],
            "b_state_mb": last_b.timing["state_bytes"] / 2 ** 20,
            "b_slots": last_b.timing["slots"], "b_reentries": last_b.timing["n_reentry"],
            "b_overflow": last_b.timing["n_overflow"],
            "when": time.strftime("%Y-%m-%d %H:%M:%S")}


def state_bytes_vs_spp(scene: str = "cornell-transient", res: int = 32, bins: int = 100,
                       spp_list: Sequence[int] = (1, 16, 256), transform: str = "identity"
                       ) -> list[dict[str, Any]]:
    """Collector (b)'s statistics state (bytes) after rendering each spp: independent of spp."""
    from ..datasets.scenes import catalogue as scenes
    from ..datasets.transient import load as tr

    sc = scenes.get(scene)
    rows = []
    for spp in spp_list:
        out = tr.collect_in_integrator(sc, res, int(spp), 0, bins, transform)
        rows.append({"spp": int(spp), "state_bytes": int(out.timing["state_bytes"]),
                     "voxels": res * res * sc.window(bins).bins * 3,
                     "max_non_zero": int(out.non_zero.max()),
                     "n_overflow": int(out.timing["n_overflow"]),
                     "layout": out.timing["sums_layout"]})
    return rows
