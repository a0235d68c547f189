"""``<out>/sweep.json``: a sweep folder's settings and the history of the runs that filled it.

``config`` holds the settings every cell of the folder shares (:data:`SETTINGS`) and the union of
the methods, scenes, spp and labels of its runs; ``runs`` holds one entry per ``dbench sweep``
run into the folder, in order: when it started and ended, how it ended (``finished``,
``interrupted``, ``failed``, or ``killed`` for a run that never wrote its end), what it asked for
(``request``), the cells it computed (``cells``), reused and skipped, and its wall time (README.md,
the ``dbench sweep`` paragraph). The file is only written by the sweep holding the folder's lock
(:mod:`dbench.run.sweep_lock`).

The file is read strictly: one that does not parse, or whose settings have the wrong types, is
refused with one line naming it and the problem, and left as it is, so that a resume never
replaces a history it could not read.
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
            "frames", "bins")
#: Settings that ``--rerun`` may change: the cells whose identity they change are recomputed.
RERUN_SETTINGS = ("ref_spp",)


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_str_list(v: Any) -> bool:
    return isinstance(v, list) and all(isinstance(x, str) for x in v)


#: (key of ``config``, check, what it should be)
_TYPES = (
    ("methods", _is_str_list, "a list of names"),
    ("scenes", _is_str_list, "a list of names"),
    ("labels", _is_str_list, "a list of names"),
    ("metrics", _is_str_list, "a list of names"),
    ("spp", lambda v: isinstance(v, list) and all(_is_int(x) for x in v),
     "a list of integers"),
    ("res", lambda v: v is None or _is_int(v) or isinstance(v, str), "a size or null"),
    ("ref_spp", lambda v: v is None or _is_int(v), "an integer or null"),
    ("ref_spp_default", lambda v: v is None or _is_int(v), "an integer or null"),
    ("frames", lambda v: v is None or _is_int(v), "an integer or null"),
    ("bins", lambda v: v is None or _is_int(v), "an integer or null"),
    ("seed", _is_int, "an integer"),
    ("seeds", _is_int, "an integer"),
    ("repeats", _is_int, "an integer"),
    ("lam", lambda v: _is_int(v) or isinstance(v, float), "a number"),
    ("transform", lambda v: v is None or isinstance(v, str), "a name or null"),
    ("device", lambda v: isinstance(v, str), "a name"),
    ("series", lambda v: isinstance(v, dict), "an object"),
    ("scene_params", lambda v: isinstance(v, dict), "an object"),
    ("scene_labels", lambda v: isinstance(v, dict), "an object"),
)


def problem(stored: Any) -> str:
    """Why a parsed sweep.json cannot be used ('' when it can)."""
    if not isinstance(stored, dict):
        return f"not a JSON object ({type(stored).__name__})"
    config = stored.get("config")
    if not isinstance(config, dict):
        return "config is missing or not an object"
    for key, ok, what in _TYPES:
        if key in config and not ok(config[key]):
            return f"config.{key} is {json.dumps(config[key])[:60]}, not {what}"
    runs = stored.get("runs", [])
    if not isinstance(runs, list) or not all(isinstance(r, dict) for r in runs):
        return "runs is not a list of objects"
    return ""


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
    for key in ("cache", "no_cache", "rerun"):
        d.pop(key, None)
    d["ref_spp"] = config.ref_spp  # as asked; the resolved value is in every cell's identity
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
        return {"config": new, "machine": machine_info(), "runs": []}
    old = dict(stored["config"])
    old.setdefault("seeds", 1)
    # a stored config without a recorded default ran under the one in effect now as far as
    # can be told; the cells' identities still catch a reference that changed
    now = effective_ref_spp(new, datasets.reference_spp())
    then = effective_ref_spp(old, now)
    differ = [k for k in SETTINGS if _value(old, k, then) != _value(new, k, now)]
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
    new.pop("params", None)
    return {**stored, "config": new, "runs": list(stored.get("runs", []))}


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
                run["status"] = "killed"
        self.entry = {"started": _now(), "status": "running", "request": config_dict(config),
                      "cells": 0, "reused": reused, "skipped": skipped,
                      "executor": executor, "workers": workers, "machine": machine_label()}
        self.stored = to_write
        self.stored["runs"].append(self.entry)
        io.write_json(self.out / "sweep.json", self.stored)

    def end(self, status: str, computed: int, references_s: float | None = None,
            error: str | None = None) -> None:
        self.entry.update(status=status, ended=_now(), cells=computed,
                          wall_s=round(time.perf_counter() - self.t0, 1))
        if references_s is not None:
            self.entry["references_s"] = round(references_s, 1)
        if error:
            self.entry["error"] = error[:300]
        io.write_json(self.out / "sweep.json", self.stored)


def _now() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%S%z")


__all__ = ["RERUN_SETTINGS", "RunRecord", "SETTINGS", "config_dict", "effective_ref_spp",
           "problem", "read", "stored_config"]
