"""How dbench's render of a Mitsuba XML scene file differs from the file, stated with every frame
(README.md, "Mitsuba scene files").

:func:`record` gathers it: the integrator that renders and the file's
(:mod:`dbench.datasets.scene_files.integrator`), its depths, the reconstruction filter and sampler
dbench uses and the file's, the camera kind, and the conversions to the RGB variant
(:mod:`dbench.datasets.scene_files.rgb`). A steady frame of a scene file carries it in
``frame.meta["scene_file"]``, and :func:`report_lines` in ``frame.meta["scene_file_settings"]``
({label: text}, for the run's report).

The film's filter is always a box: each 1-spp pass must keep each sample in its own pixel, as
the per-sample statistics need. The sampler is always ``independent`` with dbench's seeds.
"""
from __future__ import annotations

from ..mitsuba_env import mitsuba
from .integrator import IntegratorPlan
from .xml import children

FILTER = "box"
SAMPLER = "independent"
#: what Mitsuba uses where the file names none (hdrfilm's filter; a sensor's sampler)
FILE_DEFAULT_FILTER = "gaussian"
FILE_DEFAULT_SAMPLER = "independent"


def film_settings(state) -> tuple[str, str]:
    """(reconstruction filter, sampler) of the file's first sensor, by plugin name."""
    mi = mitsuba()
    sensors = children(state, state.root, mi.ObjectType.Sensor)
    if not sensors:
        return FILE_DEFAULT_FILTER, FILE_DEFAULT_SAMPLER
    sensor = sensors[0][1]
    samplers = children(state, sensor, mi.ObjectType.Sampler)
    films = children(state, sensor, mi.ObjectType.Film)
    filters = children(state, films[0][1], mi.ObjectType.ReconstructionFilter) if films else []
    return (filters[0][1].props.plugin_name() if filters else FILE_DEFAULT_FILTER,
            samplers[0][1].props.plugin_name() if samplers else FILE_DEFAULT_SAMPLER)


def record(plan: IntegratorPlan, state, sensor: str, conversions: tuple[str, ...],
           film: tuple[int, int] | None = None, sensors: int = 1) -> dict:
    """The record of the render of a file (module docstring); plain values only. ``film``:
    the (width, height) the file's film declares; ``sensors``: how many the file has (the
    first renders, as in Mitsuba)."""
    file_filter, file_sampler = film_settings(state)
    return {"integrator": plan.integrator, "file_integrator": plan.file_integrator,
            "max_depth": plan.max_depth, "rr_depth": plan.rr_depth,
            "hide_emitters": plan.hide_emitters, "replaced": plan.replaced,
            "integrator_notes": list(plan.notes), "filter": FILTER, "file_filter": file_filter,
            "sampler": SAMPLER, "file_sampler": file_sampler, "sensor": sensor,
            "conversions": list(conversions), "sensors": int(sensors),
            "file_film": list(film) if film else None}


def report_lines(rec: dict, res=None) -> dict[str, str]:
    """{label: text} of a :func:`record` for a report's settings, e.g. ``"integrator": "path
    (file: direct) — replaced because …"``; with ``res``, the size rendered, the film as
    rendered against the file's (:func:`film_text`)."""
    name, file = rec["integrator"], rec["file_integrator"]
    if rec["replaced"]:
        integrator = f"{name} (file: {file}) — replaced because {rec['replaced']}"
    elif file == name:
        integrator = f"{name} (as in the file)"
    else:
        integrator = f"{name} (file: {file or 'none'})"
    if rec["integrator_notes"]:
        integrator += " — " + "; ".join(rec["integrator_notes"])
    depth = rec["max_depth"]
    extra = (["unlimited"] if depth == -1 else [f"{name} has none"] if depth is None else [])
    if rec["rr_depth"] is not None:
        extra.append(f"rr_depth {rec['rr_depth']}")
    if rec["hide_emitters"] is not None:
        extra.append(f"hide_emitters {str(rec['hide_emitters']).lower()}")
    depth_text = ("none" if depth is None else str(depth)) + (
        f" ({'; '.join(extra)})" if extra else "")
    lines = {"integrator": integrator, "max_depth": depth_text,
             "filter": _kept_or(rec["filter"], rec["file_filter"],
                                "each 1-spp pass keeps its samples in their own pixels, as the "
                                "per-sample statistics need"),
             "sampler": _kept_or(rec["sampler"], rec["file_sampler"], "dbench's seeds"),
             "sensor": f"{rec['sensor']} (the file's pose, clip planes and field of view"
                       + (f"; the first of its {rec['sensors']} sensors, as Mitsuba renders"
                          if rec.get("sensors", 1) > 1 else "") + ")"}
    if rec.get("file_film"):
        lines["film"] = film_text(rec["file_film"], res)
    if rec["conversions"]:
        lines["conversions"] = "; ".join(rec["conversions"])
    return lines


def film_text(file_film, res=None) -> str:
    """The film: ``16×16 in the file``; rendered at ``res`` of another shape, the change in the
    report's form ("X (file: Y) — why"): the field of view is kept along the smaller side
    (README.md, "Mitsuba scene files"), so the view's aspect changes."""
    from ...resolution import parse_res

    fw, fh = (int(v) for v in file_film)
    if res is None:
        return f"{fw}×{fh} in the file"
    res = parse_res(res)
    if fw * res.height == fh * res.width:
        return f"{res.width}×{res.height} (the file's {fw}×{fh}, the same shape)"
    return (f"{res.width}×{res.height} (file: {fw}×{fh}) — the requested size; the field of "
            "view is kept along the smaller side, so the view's aspect changes")


def _kept_or(used: str, file: str, why: str) -> str:
    return f"{used} (as in the file)" if used == file else f"{used} (file: {file}) — {why}"


__all__ = ["record", "report_lines", "film_settings", "film_text", "FILTER", "SAMPLER"]
