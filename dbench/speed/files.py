"""Speed of the "bring your own" paths, as same-run ratios (issue: open dbench).

- :func:`bench_scene_file`: the Cornell box written as a Mitsuba XML file and rendered through
  :mod:`dbench.datasets.scene_files.load`, against the catalogue's ``cornell`` (the same scene, the
  same batch-sensor sample loop), same size and spp, in one process: time ratio and the
  difference of the two images' means (the same scene, independent samples).
- :func:`bench_plugin_discovery`: what scanning the installed distributions for ``dbench.*``
  entry points adds to start-up, measured in fresh interpreters.

``dbench bench scene-file`` and ``dbench bench plugins`` print them; ``--out FILE`` appends
the JSON record.
"""
from __future__ import annotations

import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from ..resolution import parse_res
from ..run.machine import machine_info
from .timing import median_time


def _matrix(transform) -> str:
    m = np.array(transform.matrix, dtype=np.float64).reshape(4, 4)
    return " ".join(f"{v:.9g}" for v in m.ravel())


def cornell_xml(mi) -> str:
    """The catalogue's ``cornell`` (Mitsuba's built-in Cornell box, its light with a black
    BSDF) as a Mitsuba 3 XML document."""
    d = mi.cornell_box()
    s = d["sensor"]
    out = ['<scene version="3.0.0">',
           '  <integrator type="path"><integer name="max_depth" value="8"/></integrator>',
           f'  <sensor type="perspective"><float name="fov" value="{s["fov"]}"/>'
           f'<string name="fov_axis" value="{s["fov_axis"]}"/>'
           f'<float name="near_clip" value="{s["near_clip"]}"/>'
           f'<float name="far_clip" value="{s["far_clip"]}"/>'
           f'<transform name="to_world"><matrix value="{_matrix(s["to_world"])}"/></transform>'
           '<film type="hdrfilm"><integer name="width" value="256"/>'
           '<integer name="height" value="256"/></film></sensor>']
    for key, v in d.items():
        if isinstance(v, dict) and v.get("type") == "diffuse":
            rgb = " ".join(map(str, v["reflectance"]["value"]))
            out.append(f'  <bsdf type="diffuse" id="{key}"><rgb name="reflectance" '
                       f'value="{rgb}"/></bsdf>')
    for key, v in d.items():
        if not (isinstance(v, dict) and v.get("type") in ("rectangle", "cube")):
            continue
        parts = [f'  <shape type="{v["type"]}" id="{key}">',
                 f'<transform name="to_world"><matrix value="{_matrix(v["to_world"])}"/>'
                 '</transform>']
        if "emitter" in v:
            rgb = " ".join(map(str, v["emitter"]["radiance"]["value"]))
            parts += ['<bsdf type="diffuse"><rgb name="reflectance" value="0"/></bsdf>',
                      f'<emitter type="area"><rgb name="radiance" value="{rgb}"/></emitter>']
        else:
            parts.append(f'<ref id="{v["bsdf"]["id"]}"/>')
        out.append("".join(parts) + "</shape>")
    out.append("</scene>")
    return "\n".join(out)


def bench_scene_file(res=256, spp: int = 64, repeats: int = 3) -> dict[str, Any]:
    """Render time of the Cornell box from an XML file against the catalogue's, same run."""
    from ..datasets import render
    from ..datasets.scenes import catalogue as scenes
    from ..datasets.mitsuba_env import mitsuba

    res = parse_res(res)
    mi = mitsuba()
    catalogue = scenes.get("cornell")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "cornell.xml"
        path.write_text(cornell_xml(mi), encoding="utf-8")
        from_file = scenes.get(str(path))
        t_cat = median_time(lambda: render.render_passes(catalogue, res, spp, progress=False),
                            repeats)
        t_xml = median_time(lambda: render.render_passes(from_file, res, spp, progress=False),
                            repeats)
        a = render.render_passes(catalogue, res, spp, seed=1, progress=False)[0]
        b = render.render_passes(from_file, res, spp, seed=2, progress=False)[0]
    return {"benchmark": "scene-file", "res": res.key, "spp": spp,
            "catalogue_s": t_cat, "xml_s": t_xml, "ratio_xml_vs_catalogue": t_xml / t_cat,
            "mean_catalogue": float(a.mean()), "mean_xml": float(b.mean()),
            "machine": machine_info()["cpu"], "when": time.strftime("%Y-%m-%d %H:%M:%S")}


# the built-in methods load with dbench.registry (its import of dbench.methods)
_STARTUP = ("import time, sys; t0 = time.perf_counter(); import dbench.registry; "
            "import dbench.plugins as p; t1 = time.perf_counter(); {scan}; "
            "print(t1 - t0, time.perf_counter() - t1)")


def bench_plugin_discovery(repeats: int = 5) -> dict[str, Any]:
    """Seconds of the entry-point scan (``plugins.discover_entry_points``) after the built-in
    methods are loaded, median over ``repeats`` fresh interpreters, with the built-ins' own
    load time for scale."""
    builtins, scans = [], []
    for _ in range(repeats):
        text = subprocess.run([sys.executable, "-c",
                               _STARTUP.format(scan="p.discover_entry_points()")],
                              capture_output=True, text=True, check=True).stdout.split()
        builtins.append(float(text[-2]))
        scans.append(float(text[-1]))
    return {"benchmark": "plugins", "builtins_s": statistics.median(builtins),
            "discovery_s": statistics.median(scans), "repeats": repeats,
            "machine": machine_info()["cpu"], "when": time.strftime("%Y-%m-%d %H:%M:%S")}


def format_result(result: dict[str, Any]) -> str:
    if result["benchmark"] == "plugins":
        return (f"plugin discovery (entry points dbench.methods / dbench.scenes): "
                f"{result['discovery_s'] * 1e3:.1f} ms, after {result['builtins_s']:.2f} s of "
                f"built-in methods (median of {result['repeats']} fresh interpreters)")
    return (f"scene file benchmark: Cornell box at {result['res']}, {result['spp']} spp\n"
            f"  catalogue scene      {result['catalogue_s']:.3f} s\n"
            f"  the same as XML file {result['xml_s']:.3f} s "
            f"({result['ratio_xml_vs_catalogue']:.2f}x)\n"
            f"  image means {result['mean_catalogue']:.4f} (catalogue) and "
            f"{result['mean_xml']:.4f} (file), independent samples")


__all__ = ["bench_scene_file", "bench_plugin_discovery", "cornell_xml", "format_result"]
