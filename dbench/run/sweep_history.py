"""``<out>/sweep.json``: a sweep folder's settings and the history of the runs that filled it.

``config`` holds the settings every cell of the folder shares (:data:`SETTINGS`) and the union of
the methods, scenes, spp and labels of its runs; ``runs`` holds one entry per ``dbench sweep``
run into the folder, in order: when it started and ended, how it ended (``finished``,
``interrupted``, ``failed``, or ``killed`` for a run that never wrote its end), what it asked for
(``request``), the cells it wrote (``cells``; ``failed`` of them are error cells), reused and
skipped, its wall time, and ``notes`` for the report where it has any (the plugins its ``all``
left out; README.md, the ``dbench sweep`` paragraph). ``config.scene_params_by_scene`` holds
each scene's own ``--scene-param`` values, those given for every scene included (its cells'
identities hold them too, through the scene's fingerprint). ``cells`` and ``failed`` are
counted from the cell files the run left (:func:`tally`), not from the results that reached the
sweep process: a group interrupted half-way, or finished by a pool worker whose result never
arrived, has still written its first cells. The file is only written by the sweep holding the
folder's lock (:mod:`dbench.run.sweep_lock`).

The file is read strictly: one that does not parse, or any of whose fields (``config``, its
settings and series, ``machine``, each of ``runs``) has the wrong type, is refused with one line
naming it, the field, what it should be and what it is, and left as it is, so that a resume
never replaces a history it could not read.
"""
from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

from .. import io
from ..errors import DbenchInputError

#: Settings every cell of one sweep folder shares; methods, scenes and spp may be extended.
SETTINGS = ("res", "ref_spp", "seed", "seeds", "repeats", "transform", "lam", "metrics",
            "frames", "bins", "normal_encoding")
#: Settings that ``--rerun`` may change: the cells whose identity they change are recomputed.
RERUN_SETTINGS = ("ref_spp",)


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_num(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _is_str_list(v: Any) -> bool:
    return isinstance(v, list) and all(isinstance(x, str) for x in v)


def _shown(v: Any) -> str:
    return json.dumps(v)[:60]


# A check takes (value, the field's name) and says what is wrong ('' when nothing is).
def _value_check(ok, what: str):
    return lambda v, where: "" if ok(v) else f"{where} is {_shown(v)}, not {what}"


def _fields(checks: dict, what: str):
    """An object whose named fields each pass their check (fields not named, or absent, are
    not checked: older files lack the newer ones)."""
    def check(v, where):
        if not isinstance(v, dict):
            return f"{where} is {_shown(v)}, not {what}"
        for key, sub in checks.items():
            if key in v and (why := sub(v[key], f"{where}.{key}")):
                return why
        return ""
    return check


def _each_value(sub, what: str):
    """An object whose every value passes ``sub`` (keys are names)."""
    def check(v, where):
        if not isinstance(v, dict):
            return f"{where} is {_shown(v)}, not {what}"
        return next((why for k, x in v.items() if (why := sub(x, f"{where}.{k}"))), "")
    return check


_NAMES = _value_check(_is_str_list, "a list of names")
_NAME = _value_check(lambda v: isinstance(v, str), "a name")
_NAME_OR_NULL = _value_check(lambda v: v is None or isinstance(v, str), "a name or null")
_TEXT = _value_check(lambda v: isinstance(v, str), "a string")
_INT = _value_check(_is_int, "an integer")
_INT_OR_NULL = _value_check(lambda v: v is None or _is_int(v), "an integer or null")
_NUMBER = _value_check(_is_num, "a number")
_OBJECT = _value_check(lambda v: isinstance(v, dict), "an object")
#: {method: {parameter: value}}, as --param gives them
_PARAMS = _each_value(_OBJECT, "an object ({method: {parameter: value}})")

#: --scene-param values: {parameter: value}
_SCENE_PARAMS = _each_value(
    _value_check(lambda v: v is None or isinstance(v, (str, int, float, bool)),
                 "a value (string or number)"), "an object ({parameter: value})")

#: a sweep's settings (``config``) and each run's ``request`` (:func:`config_dict`)
_CONFIG = {
    "methods": _NAMES, "scenes": _NAMES, "labels": _NAMES, "metrics": _NAMES,
    "spp": _value_check(lambda v: isinstance(v, list) and all(_is_int(x) for x in v),
                        "a list of integers"),
    "res": _value_check(lambda v: v is None or _is_int(v) or isinstance(v, str),
                        "a size or null"),
    "ref_spp": _INT_OR_NULL, "ref_spp_default": _INT_OR_NULL, "frames": _INT_OR_NULL,
    "bins": _INT_OR_NULL, "seed": _INT, "seeds": _INT, "repeats": _INT, "lam": _NUMBER,
    "transform": _NAME_OR_NULL, "device": _NAME, "normal_encoding": _NAME_OR_NULL,
    "params": _PARAMS,
    "series": _each_value(_fields({"method": _NAME, "params": _OBJECT},
                                  "an object ({\"method\": name, \"params\": object})"),
                          "an object ({label: {\"method\": name, \"params\": object}})"),
    "scene_params": _SCENE_PARAMS,
    "scene_params_by_scene": _each_value(_SCENE_PARAMS,
                                         "an object ({scene: {parameter: value}})"),
    "scene_labels": _each_value(_NAME, "an object ({scene: label})"),
}
#: what :func:`dbench.run.machine.machine_info` records
_MACHINE = {"cpu": _TEXT, "cores": _INT_OR_NULL, "usable_cores": _INT_OR_NULL,
            "python": _TEXT, "platform": _TEXT,
            "gpu": _TEXT, "packages": _each_value(_TEXT, "an object ({package: version})"),
            "memory": _TEXT}
#: the statuses a run's entry can have (module docstring)
STATUSES = ("running", "finished", "interrupted", "failed", "killed")
#: one entry of ``runs`` (:class:`RunRecord`)
_RUN = {"started": _TEXT, "ended": _TEXT,
        "status": _value_check(lambda v: v in STATUSES, "one of " + ", ".join(STATUSES)),
        "request": _fields(_CONFIG, "an object"), "cells": _INT, "failed": _INT,
        "reused": _INT, "skipped": _INT, "executor": _NAME, "workers": _INT, "machine": _TEXT,
        "notes": _value_check(_is_str_list, "a list of lines"),
        "wall_s": _NUMBER, "references_s": _NUMBER, "error": _TEXT}


def problem(stored: Any) -> str:
    """Why a parsed sweep.json cannot be used ('' when it can): the first field of the wrong
    type, named by its place (``config.series.jbf.params``, ``runs[2].cells``), with what it
    should be and what it is."""
    if not isinstance(stored, dict):
        return f"not a JSON object ({type(stored).__name__})"
    if "config" not in stored:
        return "config is missing"
    checks = {"config": _fields(_CONFIG, "an object"),
              "machine": _fields(_MACHINE, "an object (cpu, cores, python, platform, gpu, "
                                           "packages)")}
    for key, check in checks.items():
        if key in stored and (why := check(stored[key], key)):
            return why
    runs = stored.get("runs", [])
    if not isinstance(runs, list):
        return f"runs is {_shown(runs)}, not a list of objects"
    run = _fields(_RUN, "an object")
    return next((why for i, r in enumerate(runs) if (why := run(r, f"runs[{i}]"))), "")


def read(out: Path) -> dict | None:
    """The folder's sweep.json, or None when there is none; DbenchInputError naming the file
    and the problem when it cannot be used (the file is left untouched)."""
    path = Path(out) / "sweep.json"
    if not path.exists():
        return None
    hint = ("; it is left as it is: repair it or move it away to start the sweep afresh "
            "(its cells are kept)")
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise DbenchInputError(f"{path}: cannot be read ({getattr(exc, 'strerror', None) or exc})"
                               + hint) from None
    try:
        stored = json.loads(text)
    except ValueError as exc:
        raise DbenchInputError(f"{path}: not valid JSON ({exc})" + hint) from None
    why = problem(stored)
    if why:
        raise DbenchInputError(f"{path}: {why}" + hint)
    return stored


def config_dict(config) -> dict:
    """A SweepConfig as stored in sweep.json (where renders are cached, whether they are, and
    ``--rerun`` do not change results and are left out)."""
    from .. import datasets

    d = dict(config.__dict__)
    for key in ("cache", "no_cache", "rerun", "notes"):  # notes: the run's (RunRecord)
        d.pop(key, None)
    d["ref_spp"] = config.ref_spp  # as asked; the resolved value is in every cell's identity
    # each scene's own --scene-param values (its cells' identity holds them too), so that the
    # record says what every scene was rendered with, however they were given
    own = {s: config.params_of(s) for s in config.scenes}
    d["scene_params_by_scene"] = {s: v for s, v in own.items() if v}
    # the default in effect when none is asked, so that a resume compares what was used
    d["ref_spp_default"] = datasets.reference_spp() if config.ref_spp is None else None
    labels = config.labels()
    d["labels"] = [labels[m] for m in config.methods]
    d["series"] = {labels[m]: {"method": m, "params": config.params.get(m, {})}
                   for m in config.methods}
    return json.loads(json.dumps(d, default=str))


def effective_ref_spp(config: dict, fallback: int | None) -> int | None:
    """The reference spp a stored config used: the one asked for, else the default then in
    effect (``fallback`` when the file predates recording it)."""
    if config.get("ref_spp") is not None:
        return config["ref_spp"]
    return config.get("ref_spp_default") if config.get("ref_spp_default") is not None \
        else fallback


def _value(config: dict, key: str, fallback: int | None) -> Any:
    return effective_ref_spp(config, fallback) if key == "ref_spp" else config.get(key)


def stored_config(out: Path, config, stored: dict | None) -> dict:
    """The sweep.json to write before this run (config merged, history kept); refuses
    settings other than the stored ones (``--rerun`` may change :data:`RERUN_SETTINGS`)."""
    from .. import datasets
    from .machine import machine_info
    from .sweep_names import scene_labels

    new = config_dict(config)
    # the names the cells are filed under, so that a report finds the grid's cells
    new["scene_labels"] = scene_labels(config, out)
    if stored is None:
        _check_new_folder(out)
        return {"config": new, "machine": machine_info(), "runs": []}
    old = dict(stored["config"])
    old.setdefault("seeds", 1)
    # a stored config without a recorded default ran under the one in effect now as far as
    # can be told; the cells' identities still catch a reference that changed
    now = effective_ref_spp(new, datasets.reference_spp())
    then = effective_ref_spp(old, now)
    differ = [k for k in SETTINGS if _value(old, k, then) != _value(new, k, now)]
    if "transform" in differ and _same_transforms(old, new, config):
        differ.remove("transform")
        new["transform"] = old.get("transform")  # the folder keeps what its cells were made with
    if getattr(config, "rerun", False):
        differ = [k for k in differ if k not in RERUN_SETTINGS]
    if differ:
        only_ref = all(k in RERUN_SETTINGS for k in differ)
        raise DbenchInputError(
            f"--out {out}: holds a sweep with other settings ("
            + ", ".join(f"{k}: {_value(old, k, then)!r} there, {_value(new, k, now)!r} now"
                        for k in differ)
            + ("); use --rerun to recompute its cells with the new reference, another --out, "
               "or the same settings" if only_ref else
               "); use another --out or the same settings to resume or extend it"))
    # Extending a sweep with more methods, scenes, spp or parameter sets keeps every cell.
    for key in ("methods", "scenes", "spp", "labels"):
        new[key] = old.get(key, []) + [v for v in new[key] if v not in old.get(key, [])]
    new["series"] = {**old.get("series", {}), **new["series"]}
    new["scene_labels"] = {**old.get("scene_labels", {}), **new["scene_labels"]}
    # the scenes of earlier runs keep their values; this run's scenes have theirs (none too)
    new["scene_params_by_scene"] = {
        **{s: v for s, v in old.get("scene_params_by_scene", {}).items()
           if s not in config.scenes}, **new["scene_params_by_scene"]}
    new.pop("params", None)
    return {**stored, "config": new, "runs": list(stored.get("runs", []))}


def _same_transforms(old: dict, new: dict, config) -> bool:
    """Whether this run's scenes get the transform the stored sweep gave them: ``--transform
    box-cox`` is what a sweep without ``--transform`` used for its steady scenes (None means
    each kind's default, dbench.datasets.default_transform)."""
    from .. import datasets
    from ..datasets.scenes import catalogue

    kinds = {catalogue.get(n, config.params_of(n) or None).kind for n in config.scenes}
    return all((old.get("transform") or datasets.default_transform(k))
               == (new.get("transform") or datasets.default_transform(k)) for k in kinds)


def _check_new_folder(out: Path) -> None:
    """Refuse to start a sweep in a folder holding files of something else (no sweep.json, no
    cells): its report would be written among them. The sweep's own lock is not counted; a
    folder of cells whose sweep.json was moved away starts afresh, keeping its cells."""
    from .sweep_lock import LOCK_NAME

    others = sorted(p.name for p in Path(out).iterdir() if p.name != LOCK_NAME) \
        if Path(out).is_dir() else []
    if others and "cells" not in others:
        shown = ", ".join(others[:3]) + (", ..." if len(others) > 3 else "")
        raise DbenchInputError(f"--out {out}: holds other files ({shown}) and no sweep.json; "
                               f"give a new or empty folder, or a sweep's folder")


class RunRecord:
    """This run's entry of the history: written when the run starts (``running``) and
    completed when it ends; an entry still ``running`` when the next run takes the folder's
    lock belonged to a run that was killed."""

    def __init__(self, out: Path, to_write: dict, config, executor: str, workers: int,
                 reused: int, skipped: int) -> None:
        from .machine import machine_label

        self.out = Path(out)
        self.t0 = time.perf_counter()
        for run in to_write["runs"]:
            if run.get("status") == "running":
                # it never wrote its end: its cells are those written since it started (the
                # lock kept every other run out of the folder meanwhile)
                run.update(status="killed", **cells_since(self.out, run.get("started")))
        self.entry = {"started": _now(), "status": "running", "request": config_dict(config),
                      "cells": 0, "failed": 0, "reused": reused, "skipped": skipped,
                      "executor": executor, "workers": workers, "machine": machine_label(),
                      # what the run left out of "all" (a broken plugin), for the report
                      **({"notes": list(config.notes)} if getattr(config, "notes", None)
                         else {})}
        self.stored = to_write
        self.stored["runs"].append(self.entry)
        io.write_json(self.out / "sweep.json", self.stored)

    def end(self, status: str, written: dict[str, int], references_s: float | None = None,
            error: str | None = None) -> None:
        """Complete the entry: ``status`` (:data:`STATUSES`), ``written`` the run's
        :func:`tally`."""
        self.entry.update(status=status, ended=_now(), cells=written["cells"],
                          failed=written["failed"],
                          wall_s=round(time.perf_counter() - self.t0, 1))
        if references_s is not None:
            self.entry["references_s"] = round(references_s, 1)
        if error:
            self.entry["error"] = error[:300]
        io.write_json(self.out / "sweep.json", self.stored)


def cells_since(out: Path, started: Any) -> dict[str, int]:
    """{"cells", "failed"}: the cell files under ``out/cells`` written at or after ``started``
    (a run entry's ``started`` text), as :func:`tally` counts them; {} when it is unreadable."""
    from datetime import datetime

    try:  # to the second, as _now writes it: a cell of that second counts
        t0 = datetime.strptime(str(started), "%Y-%m-%dT%H:%M:%S%z").timestamp()
    except (ValueError, OverflowError):
        return {}

    def since(path: Path) -> bool:
        try:
            return path.stat().st_mtime >= t0
        except OSError:
            return False
    return _count(p for p in (Path(out) / "cells").rglob("*.json") if since(p))


def snapshot(paths) -> dict[Path, tuple | None]:
    """{cell path: what is there before the run} for the cells a run is to compute: the file's
    (inode, size, mtime) or None when there is none. A cell file is replaced by renaming a new
    file onto it (:func:`dbench.io.atomic_path`), so a file written since has another inode."""
    before = {}
    for path in paths:
        try:
            st = Path(path).stat()
            before[Path(path)] = (st.st_ino, st.st_size, st.st_mtime_ns)
        except OSError:
            before[Path(path)] = None
    return before


def tally(before: dict[Path, tuple | None]) -> dict[str, int]:
    """{"cells": the cell files of ``before`` (:func:`snapshot`) that were written since,
    "failed": how many of them are error cells}: what a run computed, counted from the files it
    left, whichever way it ended (interrupted pool workers included)."""
    return _count(path for path, was in before.items() if snapshot([path])[path] != was)


def _count(paths) -> dict[str, int]:
    """{"cells": how many of the files ``paths`` are whole cells, "failed": how many of those
    are error cells}."""
    cells = failed = 0
    for path in paths:
        try:
            cell = io.read_json(path)
        except (OSError, ValueError):
            continue  # gone, or not a whole cell: computed again by the next run
        cells += 1
        failed += int(isinstance(cell, dict) and cell.get("status") == "error")
    return {"cells": cells, "failed": failed}


def _now() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%S%z")


__all__ = ["RERUN_SETTINGS", "RunRecord", "SETTINGS", "STATUSES", "config_dict",
           "effective_ref_spp", "problem", "read", "snapshot", "stored_config", "tally"]
