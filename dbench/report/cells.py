"""The cell files of a sweep folder: reading them, and which ones can be used.

A sweep writes one JSON file per (scene, spp, method label) cell,
``<out>/cells/<scene>/<spp:05d>spp/<method>.json`` (:mod:`dbench.run.sweep`; README.md, the
``dbench sweep`` paragraph). A file that does not parse, or whose fields have the wrong types,
is not a cell: the report lists it among the problems, and a resumed sweep computes that cell
again.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

from .. import io

#: Numbers an "ok" cell must carry as numbers (or null) to be read.
NUMERIC_KEYS = ("spp", "rmse", "relmse", "time_s")


def read_cell(path: Path) -> dict | None:
    """The JSON object in ``path``, or None when it cannot be read or is not an object."""
    try:
        value = io.read_json(path)
    except (OSError, ValueError):
        return None
    return value if isinstance(value, dict) else None


def cell_problem(cell: Any) -> str:
    """Why a cell file cannot be used ('' when it can)."""
    if not isinstance(cell, dict):
        return f"not a JSON object ({type(cell).__name__})"
    if cell.get("status") not in ("ok", "skipped", "error"):
        return f"status {cell.get('status')!r} is not ok, skipped or error"
    for key in ("scene", "method"):
        if not isinstance(cell.get(key), str):
            return f"{key} missing or not a string"
    if cell["status"] == "ok":
        for key in NUMERIC_KEYS:
            v = cell.get(key)
            if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float))):
                return f"{key} is {v!r}, not a number"
        if not isinstance(cell.get("spp"), int):
            return "spp missing or not an integer"
    return ""


def load_cells_checked(out: str | Path) -> tuple[list[dict], list[str]]:
    """(cells, problems): every readable cell file of a sweep folder, sorted by scene, spp,
    method, and one line per file that could not be used. Temporary files of an interrupted
    write (names starting with a dot) are not cells."""
    cells, problems = [], []
    root = Path(out)
    for p in sorted(root.glob("cells/*/*/*.json")):
        if p.name.startswith("."):
            continue
        try:
            cell = io.read_json(p)
        except (OSError, ValueError) as exc:
            problems.append(f"{p.relative_to(root).as_posix()}: unreadable ({type(exc).__name__})")
            continue
        why = cell_problem(cell)
        if why:
            problems.append(f"{p.relative_to(root).as_posix()}: {why}")
            continue
        cells.append(cell)
    cells.sort(key=lambda c: (c["scene"], c.get("spp") or 0, c["method"]))
    return cells, problems


def load_cells(out: str | Path) -> list[dict]:
    """Every usable cell file of a sweep folder, sorted by scene, spp, method."""
    return load_cells_checked(out)[0]


__all__ = ["NUMERIC_KEYS", "cell_problem", "load_cells", "load_cells_checked", "read_cell"]
