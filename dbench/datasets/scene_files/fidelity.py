"""How dbench's render of a Mitsuba XML scene file differs from the file, stated with every frame
(README.md, "Mitsuba scene files").

:func:`record` gathers it: the integrator that renders and the file's
(:mod:`dbench.datasets.scene_files.integrator`), its depths, the reconstruction filter and sampler
dbench uses and the file's, the camera kind, and the conversions to the RGB variant
(:mod:`dbench.datasets.scene_files.rgb`). A steady frame of a scene file carries it in
``frame.meta["scene_file"]``, and :func:`report_lines` in ``frame.meta["scene_file_settings"]``
({label: text}, for the run's report).

The film's filter is always a box: each 1-spp pass must keep each sample in its own pixel, as
the per-sample statistics need. The sampler is always ``independent`` with dbench's seeds, at
the spp of the run (``--spp``): a ``sample_count`` or ``seed`` the file's sampler sets is
recorded (``file_sampler_settings``) and, where the run's spp or seeds differ, the sampler line
says so. The film covers the whole view: a crop window of the file's film (``crop_offset_x``,
``crop_offset_y``, ``crop_width``, ``crop_height``) is not applied, and the film line says so.

A Python scene file's dictionary (and a plugin's build function's) gets the same record from
:func:`dict_record`: its integrator's plan, its film's filter and sampler against dbench's.
"""
from __future__ import annotations

from ..mitsuba_env import mitsuba
from ...resolution import FOV_SENSORS, focal_fov
from .integrator import IntegratorPlan
from .xml import children

FILTER = "box"
SAMPLER = "independent"
#: what Mitsuba uses where the file names none (hdrfilm's filter; a sensor's sampler)
FILE_DEFAULT_FILTER = "gaussian"
FILE_DEFAULT_SAMPLER = "independent"
#: a film's crop window (hdrfilm; Mitsuba renders only the window)
CROP_KEYS = ("crop_offset_x", "crop_offset_y", "crop_width", "crop_height")


def film_settings(state) -> tuple[str, str]:
    """(reconstruction filter, sampler) of the file's first sensor, by plugin name; ``state``
    is the file's parser state, or a ``mi.load_dict`` dictionary."""
    if isinstance(state, dict):
        sensor = state.get("sensor") if isinstance(state.get("sensor"), dict) else {}
        film = sensor.get("film", {"type": "hdrfilm"})
        rfilter = film.get("rfilter") if isinstance(film, dict) else film.rfilter()
        return (_name(rfilter, FILE_DEFAULT_FILTER),
                _name(sensor.get("sampler"), FILE_DEFAULT_SAMPLER))
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


def sampler_settings(state) -> dict[str, int]:
    """{"sample_count": n, "seed": s}, those of the two that the file's first sensor's sampler
    sets itself (Mitsuba's defaults are not the file's word); ``state`` as for
    :func:`film_settings`."""
    if isinstance(state, dict):
        sensor = state.get("sensor") if isinstance(state.get("sensor"), dict) else {}
        sampler = sensor.get("sampler")
        props = sampler if isinstance(sampler, dict) else {}
        get = props.get
    else:
        mi = mitsuba()
        sensors = children(state, state.root, mi.ObjectType.Sensor)
        samplers = children(state, sensors[0][1], mi.ObjectType.Sampler) if sensors else []
        if not samplers:
            return {}
        props = samplers[0][1].props
        keys = set(props.keys())

        def get(k):
            return props.get(k) if k in keys else None
    out = {}
    for key in ("sample_count", "seed"):
        try:
            value = get(key)
            if value is not None:
                out[key] = int(value)
        except (TypeError, ValueError):
            pass  # (Mitsuba refuses it when it loads the file)
    return out


def _name(obj, default: str) -> str:
    """The plugin name of a dictionary entry (a loaded object: its class name)."""
    if obj is None:
        return default
    if isinstance(obj, dict):
        return str(obj.get("type", default))
    return obj.class_name() if hasattr(obj, "class_name") else type(obj).__name__


def file_crop(film) -> dict | None:
    """The crop window of a loaded film, ``{"size": [w, h], "offset": [x, y]}``; None where
    the film renders its whole size."""
    size, crop, offset = ([int(v) for v in xy] for xy in
                          (film.size(), film.crop_size(), film.crop_offset()))
    return None if crop == size and offset == [0, 0] else {"size": crop, "offset": offset}


def dict_record(plan: IntegratorPlan, d: dict) -> dict:
    """The :func:`record` of a build dictionary ``d`` (module docstring): dbench gives its
    sensor its own film, sampler and field-of-view axis (dbench.datasets.scenes.build.own_camera)
    and keeps the rest of the sensor; a crop window of its film is named by its keys."""
    sensor = d.get("sensor") if isinstance(d.get("sensor"), dict) else {}
    film = sensor.get("film")
    crop = [k for k in CROP_KEYS if isinstance(film, dict) and k in film]
    rec = record(plan, d, str(sensor.get("type", "perspective")), (),
                 crop={"keys": crop} if crop else None)
    axis = sensor.get("fov_axis")
    fov = "its fov is read along x"
    if "fov" not in sensor and rec["sensor"] in FOV_SENSORS:  # (own_camera converts it)
        focal = sensor.get("focal_length", "50mm")
        given = "" if "focal_length" in sensor else " (Mitsuba's default)"
        fov = (f"its focal_length {focal}{given} is read as the fov along x that Mitsuba "
               f"makes of it, {focal_fov(focal, sensor.get('film')):.4g}°,")
    rec["sensor_text"] = (f"{rec['sensor']} (the file's pose and field of view: {fov} "
                          f"and kept along the image's smaller side"
                          + (f"; its fov_axis {axis} is not applied" if axis not in (None, "x")
                             else "") + ")")
    return rec


def record(plan: IntegratorPlan, state, sensor: str, conversions: tuple[str, ...],
           film: tuple[int, int] | None = None, sensors: int = 1,
           crop: dict | None = None) -> dict:
    """The record of the render of a file (module docstring); plain values only. ``film``:
    the (width, height) the file's film declares; ``sensors``: how many the file has (the
    first renders, as in Mitsuba); ``crop``: its film's crop window (:func:`file_crop`, or
    ``{"keys": [...]}`` naming the dictionary entries that set one)."""
    file_filter, file_sampler = film_settings(state)
    return {"integrator": plan.integrator, "file_integrator": plan.file_integrator,
            "max_depth": plan.max_depth, "rr_depth": plan.rr_depth,
            "hide_emitters": plan.hide_emitters, "replaced": plan.replaced,
            "integrator_notes": list(plan.notes), "filter": FILTER, "file_filter": file_filter,
            "sampler": SAMPLER, "file_sampler": file_sampler,
            "file_sampler_settings": sampler_settings(state), "sensor": sensor,
            "conversions": list(conversions), "sensors": int(sensors),
            "file_film": list(film) if film else None, "file_crop": crop}


def report_lines(rec: dict, res=None, spp: int | None = None,
                 seed: int | None = None) -> dict[str, str]:
    """{label: text} of a :func:`record` for a report's settings, e.g. ``"integrator": "path
    (file: direct) — replaced because …"``; with ``res``, the size rendered, the film as
    rendered against the file's (:func:`film_text`); with ``spp`` and ``seed``, those of the
    render against the file's sampler's (:func:`sampler_text`)."""
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
             "sampler": sampler_text(rec, spp, seed),
             "sensor": rec.get("sensor_text") or (
                 f"{rec['sensor']} (the file's pose, clip planes and field of view"
                 + (f"; the first of its {rec['sensors']} sensors, as Mitsuba renders"
                    if rec.get("sensors", 1) > 1 else "") + ")")}
    if rec.get("file_film") or rec.get("file_crop"):
        lines["film"] = film_text(rec.get("file_film"), res, rec.get("file_crop"))
    if rec["conversions"]:
        lines["conversions"] = "; ".join(rec["conversions"])
    return lines


def film_text(file_film, res=None, crop: dict | None = None) -> str:
    """The film: ``16×16 in the file``; rendered at ``res`` of another shape, the change in the
    report's form ("X (file: Y) — why"): the field of view is kept along the smaller side
    (README.md, "Mitsuba scene files"), so the view's aspect changes. A crop window of the
    file's (``crop``, :func:`record`) is stated as not applied. ``file_film`` None: a build
    dictionary's film, made at the requested size."""
    from ...resolution import parse_res

    res = None if res is None else parse_res(res)
    cropped = ""
    if crop and "keys" in crop:
        cropped = (f"the file's film sets {', '.join(crop['keys'])}, a crop window dbench does "
                   f"not apply: it renders the whole view")
    elif crop:
        (cw, ch), (cx, cy) = crop["size"], crop["offset"]
        cropped = (f"the file's crop window {cw}×{ch} at ({cx}, {cy}) is not applied: dbench "
                   f"renders the whole view")
    if file_film is None:
        size = "the requested size" if res is None else f"{res.width}×{res.height}"
        return f"{size} (file: the same size, with a crop window) — {cropped}"
    fw, fh = (int(v) for v in file_film)
    window = " with a crop window" if crop else ""
    if res is None:
        return (f"{fw}×{fh} (file: {fw}×{fh}{window}) — {cropped}" if crop
                else f"{fw}×{fh} in the file")
    if fw * res.height == fh * res.width:
        if crop:
            return (f"{res.width}×{res.height} (file: {fw}×{fh}, the same shape,{window}) — "
                    f"{cropped}")
        return f"{res.width}×{res.height} (the file's {fw}×{fh}, the same shape)"
    return (f"{res.width}×{res.height} (file: {fw}×{fh}{window}) — the requested size; the "
            "field of view is kept along the smaller side, so the view's aspect changes"
            + (f"; {cropped}" if crop else ""))


def sampler_text(rec: dict, spp: int | None = None, seed: int | None = None) -> str:
    """The sampler: ``independent (as in the file)``, or the change in the report's form, where
    the file names another sampler, its sampler sets a ``sample_count`` other than ``spp`` (the
    run's ``--spp``), or sets a ``seed`` (dbench seeds every pass itself, from ``seed``, the
    run's ``--seed``)."""
    used, file = [rec["sampler"]], [rec["file_sampler"]]
    own = rec.get("file_sampler_settings") or {}
    why = []
    if spp is not None and own.get("sample_count", spp) != spp:
        used.append(f"{spp} spp")
        file.append(f"sample_count {own['sample_count']}")
        why.append("the run's --spp sets the samples per pixel")
    if "seed" in own:
        used.append("dbench's seeds" + (f" from --seed {seed}" if seed is not None else ""))
        file.append(f"seed {own['seed']}")
    why.append("dbench's seeds")
    return _kept_or(", ".join(used), ", ".join(file), "; ".join(why))


def _kept_or(used: str, file: str, why: str) -> str:
    return f"{used} (as in the file)" if used == file else f"{used} (file: {file}) — {why}"


__all__ = ["record", "dict_record", "file_crop", "report_lines", "film_settings",
           "sampler_settings", "sampler_text", "film_text", "CROP_KEYS", "FILTER", "SAMPLER"]
