"""The cell files of a sweep folder: reading them, which ones can be used, and what they say
together (the machines, devices and Mitsuba variants they ran on; settings they mix; what
their inputs said of themselves).

A sweep writes one JSON file per (scene, spp, method label) cell,
``<out>/cells/<scene>/<spp:05d>spp/<method>.json`` (:mod:`dbench.run.sweep`; README.md, the
``dbench sweep`` paragraph). A file that does not parse, or whose fields have the wrong types,
is not a cell: the report lists it among the problems, and a resumed sweep computes that cell
again.
"""
from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any, Callable, Sequence

from .. import io
from .formats import counted, markdown_code, markdown_text

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


def expected_grid(config: dict) -> list[tuple[str, int, str]]:
    labels = config.get("labels") or config.get("methods") or []
    names = config.get("scene_labels") if isinstance(config.get("scene_labels"), dict) else {}
    try:  # cells are filed under the scene's label (a scene file's name, not its path)
        return [(str(names.get(s, s)), int(p), str(m)) for s in config.get("scenes") or []
                for p in config.get("spp") or [] for m in labels]
    except (TypeError, ValueError):
        return []


def cell_key(c: dict) -> tuple[str, int, str] | None:
    try:
        return str(c["scene"]), int(c["spp"]), str(c["method"])
    except (KeyError, TypeError, ValueError):
        return None


#: Identity keys (dbench/run/sweep.py, ``cell_identity``) that differ from cell to cell of one
#: table by design: the grid's axes and what follows from them (the reference's spp, which
#: verdicts.reference_summary states on its own; the feature buffers' spp).
PER_CELL = frozenset({"scene", "spp", "ref_spp", "feature_spp"})
#: Identity keys of the method label: the same over every cell of the label, every scene.
METHOD_KEYS = frozenset({"method", "params", "method_version", "device", "device_name"})


def _flat(identity: dict, prefix: str = "") -> dict[str, str]:
    """Dotted key → the value as JSON (``params.radius``: ``3``)."""
    out: dict[str, str] = {}
    for k, v in identity.items():
        if isinstance(v, dict) and v:
            out.update(_flat(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = json.dumps(v, sort_keys=True, default=str)
    return out


def mixed_settings(cells: Sequence[dict]) -> list[tuple[str, str, str, dict[str, list[str]]]]:
    """(kind, who, key, value → the cells that hold it) for every identity key whose value
    differs between the finished cells the report puts side by side: between the cells of one method
    label (its parameters and code, over every scene and spp: ``kind`` "label", ``who`` the
    label) or between the cells of one scene (scene content, seeds, size, transform, metric
    code: ``kind`` "scene", ``who`` the scene); names as they are (:func:`mixed_text` and
    :func:`mixed_md` write them). A sweep refuses such a mix unless ``--rerun``, and a
    ``--rerun`` over part of the grid recomputes only that part (README.md, the ``dbench
    sweep`` paragraph), so the rest keeps the old settings; cells without an identity (older
    format) are not compared."""
    ok = [c for c in cells if isinstance(c, dict) and c.get("status") == "ok"
          and isinstance(c.get("identity"), dict)]
    groups: dict[tuple[str, str], list[tuple[str, dict[str, str]]]] = {}
    for c in ok:
        flat = {k: v for k, v in _flat(c["identity"]).items()
                if k.split(".")[0] not in PER_CELL}
        groups.setdefault(("label", str(c.get("method"))), []).append(
            (f"{c.get('scene')} {c.get('spp')} spp",
             {k: v for k, v in flat.items() if k.split(".")[0] in METHOD_KEYS}))
        groups.setdefault(("scene", str(c.get("scene"))), []).append(
            (f"{c.get('spp')} spp {c.get('method')}",
             {k: v for k, v in flat.items() if k.split(".")[0] not in METHOD_KEYS}))
    out = []
    for (kind, name), members in sorted(groups.items()):
        for key in sorted({k for _, flat in members for k in flat}):
            values: dict[str, list[str]] = {}
            for where, flat in members:
                values.setdefault(flat.get(key, "(absent)"), []).append(where)
            if len(values) > 1:
                out.append((kind, name, key, values))
    return out


def _who(kind: str, who: str, name: Callable[[Any], str]) -> str:
    """A label as code (:func:`markdown_code`, plain backticks unless it holds one), a scene as
    ``name`` writes it."""
    return markdown_code(who) if kind == "label" else name(who)


def mixed_text(mixed: Sequence[tuple[str, str, str, dict]],
               where: str = 'see "Mixed settings" in README.md',
               name: Callable[[Any], str] = markdown_text) -> str:
    """The settings line's warning: who mixes which keys ('' when nothing is mixed); ``name``
    writes the scenes and the keys (:func:`markdown_text` in Markdown, ``str`` on the terminal
    and in the results page, which escapes HTML itself): a key names a method's parameter
    (``params.<name>``), which a plugin may call anything."""
    by: dict[str, list[str]] = {}
    for kind, who, key, _ in mixed:
        by.setdefault(_who(kind, who, name), []).append(name(key))
    return (f"⚠ cells computed with different settings side by side ({where}): "
            + "; ".join(f"{w}: {', '.join(k)}" for w, k in by.items()) if by else "")


def mixed_md(mixed: Sequence[tuple[str, str, str, dict]]) -> list[str]:
    """One line per mixed key: each value (shortened) and the cells that hold it, as literal
    Markdown text (:func:`markdown_text`: the cells name scenes and methods, a key a method's
    parameter)."""
    def where(cells: list[str]) -> str:
        more = f" and {len(cells) - 3} more" if len(cells) > 3 else ""
        return ", ".join(map(markdown_text, cells[:3])) + more

    def short(v: str) -> str:
        return markdown_text(v if len(v) <= 40 else v[:39] + "…")
    return [f"- {_who(kind, who, markdown_text)}: {markdown_text(key)} is "
            + "; ".join(f"{short(v)} in {where(c)}" for v, c in values.items())
            for kind, who, key, values in mixed]


def device_label(cell: dict) -> str:
    """Where a cell's method was timed: ``cpu``, ``cuda (NVIDIA H200)``; "" for cells older than
    the record (docs/gpu.md §3: every cell records ``device`` and ``device_name``)."""
    dev, name = cell.get("device"), cell.get("device_name")
    if not isinstance(dev, str) or not dev:
        return ""
    return f"{dev} ({name})" if dev != "cpu" and isinstance(name, str) and name else dev


def devices_text(cells: Sequence[dict]) -> list[str]:
    """The devices the finished cells' methods ran on, each with its cell count and, where
    there are several, its methods and a warning: a sweep on a GPU times the methods with a
    device path there and the others on the host (README.md, "On a GPU"), so ``time_s`` and
    the time plots then compare devices as well as methods."""
    by: dict[str, list[str]] = {}
    for c in cells:
        if isinstance(c, dict) and c.get("status") == "ok" and device_label(c):
            by.setdefault(device_label(c), []).append(str(c.get("method")))
    if len(by) < 2:
        return [f"methods run on {d} ({len(m)})" for d, m in by.items()]
    return ["methods run on " + "; ".join(
        f"{d} ({len(m)}: {', '.join(sorted(set(m)))})" for d, m in sorted(by.items()))
        + " (**times of different devices side by side: time_s compares devices as well as "
          "methods**)"]


def _tally(cells: list[dict], field: str) -> dict[str, int]:
    """Computed cells per value of ``field`` ("not recorded" for cells older than it); skip
    and error records time and render nothing, so they are not counted."""
    counts: dict[str, int] = {}
    for c in cells:
        if c.get("status", "ok") != "ok":
            continue
        label = c.get(field) if isinstance(c.get(field), str) and c.get(field) else "not recorded"
        counts[label] = counts.get(label, 0) + 1
    return counts


def _recorded_text(cells: list[dict], key: str, what: str, verb: str, mixed: str
                   ) -> list[str]:
    """One line of the values of ``key`` the cells record, each with its cell count
    (``{verb} A (3); B (2)``), with ``mixed`` appended where they differ; cells older than the
    record are counted as "not recorded", and where no cell records it the line says so of
    ``what``."""
    counts = _tally(cells, key)
    if not counts:
        return []
    if list(counts) == ["not recorded"]:
        return [f"{what} is not recorded ({counted(counts['not recorded'], 'cell')}, computed "
                "before cells recorded it)"]
    text = verb + " " + "; ".join(f"{k} ({v})" for k, v in sorted(counts.items()))
    return [text + (mixed if len(counts) > 1 else "")]


def machines_text(cells: list[dict]) -> list[str]:
    """Where the computed cells were timed (each cell records its machine; older cells do
    not): one entry per machine with its cell count, and a warning when they differ, since
    ``time_s`` of two machines do not compare."""
    return _recorded_text(cells, "machine", "the machine the cells were timed on",
                          "cells timed on", " (**times from different machines do not "
                          "compare**)")


def _timed_how(cell: dict) -> str:
    """How a finished cell's method was timed: ``with 2 workers side by side on 2 cores``
    (``timed_beside`` above 0; the cores from its ``machine``), ``alone``, or "" for a cell
    that does not record it (older, or from ``dbench run``)."""
    beside = cell.get("timed_beside")
    if isinstance(beside, bool) or not isinstance(beside, int):
        return ""
    if beside <= 0:
        return "alone"
    cores = re.search(r"(\d+)(?: of \d+)? cores$", str(cell.get("machine", "")))
    return f"with {beside + 1} workers side by side" + (f" on {cores[1]} cores" if cores else "")


def side_by_side_text(cells: Sequence[dict], strong: Callable[[str], str] = str) -> list[str]:
    """Where cells were timed while other cells of their sweep ran on the same machine
    (``dbench sweep --workers N`` or Ray: their ``timed_beside``), that their ``time_s``
    includes the contention, and, where others were timed alone (or do not record how), that
    the times do not compare (``strong`` marks that warning: ``**...**`` in Markdown); nothing
    where no cell was timed side by side (README.md, the ``dbench sweep`` paragraph)."""
    counts: dict[str, int] = {}
    for c in cells:
        if isinstance(c, dict) and c.get("status") == "ok":
            how = _timed_how(c) or "not recorded"
            counts[how] = counts.get(how, 0) + 1
    if not any(how.startswith("with") for how in counts):
        return []
    if len(counts) == 1:
        return [f"timed {next(iter(counts))}: time_s includes contention"]
    return ["timed " + "; ".join(f"{how} ({counted(n, 'cell')})" for how, n in
                                 sorted(counts.items(), key=lambda kv: (
                                     kv[0] != "alone", kv[0] == "not recorded", kv[0])))
            + " (" + strong("times measured side by side and alone do not compare: time_s "
                            "includes contention where timed side by side") + ")"]


def variants_text(cells: list[dict]) -> list[str]:
    """What rendered the cells' inputs and references: each cell's ``render_variant``, the
    Mitsuba variant (``llvm_ad_rgb``, ``cuda_ad_rgb``; ``files`` for a folder of renders),
    with its cell count. A CUDA render is not bit-identical to an LLVM one and takes another
    time, so cells of several variants are flagged (README.md, "How renders work")."""
    return _recorded_text(cells, "render_variant",
                          "the Mitsuba variant that rendered the inputs", "inputs rendered by",
                          " (**several variants: their inputs and references are other "
                          "samples, and their render times do not compare**)")


def input_warnings(cells: Sequence[dict]) -> list[str]:
    """``scene: warning`` for each warning the cells recorded of their inputs
    (``input_warnings``, what ``dbench run`` prints: a folder's doubtful reference or normals,
    NaN or ±Inf samples, a noisy image with nothing to denoise; dbench/run/inputs.py), once
    per scene and warning however many spp and labels carry it; ``scene at 4, 16 spp:
    warning`` where it holds at some of the scene's spp only (README.md, "How renders work");
    texts that differ only in their numbers (each spp's NaN count) as one, ``scene at 4, 16
    spp, respectively: ... (12, 48 in the noisy image ...)``. Cells older than the record say
    nothing."""
    found: dict[tuple[str, str], set[int]] = {}
    spps: dict[str, set[int]] = {}
    for c in cells:
        if not isinstance(c, dict):
            continue
        scene, said = str(c.get("scene")), c.get("input_warnings")
        spp = {c["spp"]} if isinstance(c.get("spp"), int) else set()
        spps.setdefault(scene, set()).update(spp)
        for text in said if isinstance(said, list) else []:
            found.setdefault((scene, str(text)), set()).update(spp)

    def at(scene: str, spp: set[int]) -> str:
        some = spp and spp != spps.get(scene, set())
        return f" at {', '.join(map(str, sorted(spp)))} spp" if some else ""
    return [f"{scene}{at(scene, spp) if respectively is None else respectively}: {text}"
            for (scene, text), (spp, respectively) in sorted(
                _by_counts(found).items(),
                key=lambda kv: (kv[0][0], min(kv[1][0], default=0), kv[0][1]))]


#: a number in a warning's text (a count of samples, spp, a percentage)
_NUMBER = re.compile(r"\d+(?:\.\d+)?")


def _by_counts(found: dict[tuple[str, str], set[int]]
               ) -> dict[tuple[str, str], tuple[set[int], str | None]]:
    """``found`` ((scene, text) → spp) with the texts of one scene that differ only in their
    numbers (the NaN counts of each spp's render) joined into one text whose differing numbers
    are listed in spp order, ``{scene} at 4, 16 spp, respectively`` (the second item; None
    where a text stays alone). Not joined where one spp has two such texts (the spp would not
    say which number is whose)."""
    groups: dict[tuple[str, tuple[str, ...]], list[tuple[str, set[int]]]] = {}
    for (scene, text), spp in found.items():
        groups.setdefault((scene, tuple(_NUMBER.split(text))), []).append((text, spp))
    out: dict[tuple[str, str], tuple[set[int], str | None]] = {}
    for (scene, parts), texts in groups.items():
        every = sorted(set().union(*(spp for _, spp in texts)))
        if len(texts) < 2 or not every or sum(len(spp) for _, spp in texts) != len(every):
            out.update({(scene, text): (spp, None) for text, spp in texts})
            continue
        numbers = {n: _NUMBER.findall(text) for text, spp in texts for n in spp}
        listed = []  # each number of the text: once where every spp has it, else each spp's
        for slot in zip(*(numbers[n] for n in every)):
            listed.append(slot[0] if len(set(slot)) == 1 else ", ".join(slot))
        text = "".join(part + (listed[i] if i < len(listed) else "")
                       for i, part in enumerate(parts))
        out[(scene, text)] = (set(every),
                              f" at {', '.join(map(str, every))} spp, respectively")
    return out


#: What the "Input warnings" of the README and of the results page say above their lines;
#: ``{run}``: ``dbench run`` as code in the page's format.
INPUT_WARNINGS_INTRO = ("What the inputs of these cells say of themselves, as {run} prints it "
                        "(their numbers are computed all the same):")


def grid_status(config: dict, cells: Sequence[dict]) -> dict[str, Any]:
    """Counts of the (scene, spp, label) cells the config expects by status (ok / skipped /
    error / other), the expected cells no file holds (``missing``) and the cells outside that
    grid (``outside``), so that expected = ok + skipped + error + other + missing. A config
    that names no grid (an old or missing sweep.json) expects the cells there are."""
    counts = {"ok": 0, "skipped": 0, "error": 0, "other": 0}
    grid = dict.fromkeys(expected_grid(config))
    keys = [cell_key(c) for c in cells]
    if not grid:
        grid = dict.fromkeys(k for k in keys if k is not None)
    seen, outside = set(), 0
    for c, k in zip(cells, keys):
        if k not in grid or k in seen:  # another grid's cell, or a second file of one cell
            outside += 1
            continue
        seen.add(k)
        st = c.get("status")
        counts[st if st in counts else "other"] += 1
    missing = sorted(k for k in grid if k not in seen)
    return {**counts, "expected": len(grid), "missing": missing, "outside": outside,
            "mixed": mixed_settings(cells)}


def grid_status_text(status: dict[str, Any], name: Callable[[Any], str] = markdown_text) -> str:
    """The cell counts by status in one line, with :func:`mixed_text`'s warning (``name``
    writes the scenes there)."""
    text = (f"cells: {status['expected']} expected, {status['ok']} ok, {status['skipped']} "
            f"skipped, {status['error']} error, {len(status['missing'])} missing")
    text += f", {status['other']} of unknown status" if status["other"] else ""
    outside = status.get("outside", 0)
    text += (f"; {outside} more cell{'s' if outside != 1 else ''} outside the sweep's "
             f"settings (not counted)" if outside else "")
    mixed = mixed_text(status.get("mixed") or [], name=name)
    return text + (f"; {mixed}" if mixed else "")


def missing_md(missing: Sequence[tuple[str, int, str]]) -> list[str]:
    """One line per (scene, label) listing the spp with no cell file."""
    by: dict[tuple[str, str], list[int]] = {}
    for scene, spp, label in missing:
        by.setdefault((scene, label), []).append(spp)
    return [f"- missing {markdown_text(label)} on {markdown_text(scene)} at "
            f"{', '.join(map(str, sorted(s)))} spp"
            for (scene, label), s in sorted(by.items())]


def problems_md(cells: list[dict], problems: list[str], missing) -> list[str]:
    """Skipped pairs (once per reason), errors, malformed files and missing cells."""
    lines, seen = [], set()
    for c in cells:
        if c.get("status") == "skipped":
            key = (str(c.get("method")), str(c.get("scene")), str(c.get("reason", "")))
            if key not in seen:
                seen.add(key)
                lines.append(f"- skipped {markdown_text(key[0])} on {markdown_text(key[1])}: "
                             f"{markdown_text(key[2])}")
    # an error's text is a library's (``<lambda>``, ``__init__``): escaped as the names are
    lines += [f"- error {markdown_text(c.get('method'))} on {markdown_text(c.get('scene'))} at "
              f"{c.get('spp')} spp: {markdown_text(c.get('error', ''))}"
              for c in cells if c.get("status") == "error"]
    lines += [f"- malformed cell file {p}" for p in problems]
    lines += missing_md(missing)
    return lines


def load_sweep(sweep_dir: Path) -> tuple[dict, list[dict], list[str]]:
    """(sweep.json, cells, problems): the cells and one line per file that is not a cell
    (:func:`dbench.report.cells.load_cells_checked`)."""
    sweep_dir = Path(sweep_dir)
    info = read_cell(sweep_dir / "sweep.json") or {}
    info = info if isinstance(info, dict) else {}
    cells, problems = load_cells_checked(sweep_dir)
    return info, list(cells), [str(p) for p in problems]


def wall_text(info: dict, cells: list[dict] | None = None) -> str:
    """The wall time the sweep's runs took (recorded in sweep.json by each run) and the time
    its references took to render (each distinct reference's ``ref_render_s`` from the cells,
    also when it was rendered by an earlier, interrupted run); '' when nothing was recorded."""
    runs = [r for r in info.get("runs", []) if isinstance(r, dict)]
    refs: dict[tuple, float] = {}
    for c in cells or []:
        t = c.get("ref_render_s")
        if isinstance(t, (int, float)) and not isinstance(t, bool):
            refs[(c.get("scene"), c.get("ref_spp"), c.get("ref_seed"))] = float(t)
    parts = []
    if runs:
        wall = sum(float(r.get("wall_s", 0)) for r in runs)
        cells_n = sum(int(r.get("cells", 0)) for r in runs)
        parts.append(f"wall time {wall:.0f} s for the last {counted(cells_n, 'cell')} "
                     f"computed ({counted(len(runs), 'run')})")
    if refs:
        parts.append(f"{counted(len(refs), 'reference')} rendered in "
                     f"{sum(refs.values()):.0f} s in all")
    return ", ".join(parts + machines_text(cells or []) + devices_text(cells or [])
                     + side_by_side_text(cells or [], lambda s: f"**{s}**")
                     + variants_text(cells or []))


def _notes(info: dict) -> list[tuple[str, str]]:
    runs = [r for r in info.get("runs", []) if isinstance(r, dict)]
    return [(f"run {i} ({r.get('started', '?')})", str(note))
            for i, r in enumerate(runs, 1) for note in r.get("notes") or []]


def run_notes(info: dict) -> list[str]:
    """The notes the sweep's runs recorded in sweep.json (what a run's ``--methods all`` or
    ``--scenes all`` left out: dbench.run.sweep_history), each as plain text with the run it
    came from, ``run 2 (<started>): <note>``; none where no run noted anything."""
    return [f"{run}: {note}" for run, note in _notes(info)]


def run_notes_md(info: dict) -> list[str]:
    """:func:`run_notes` as Markdown lines under "Notes of the runs:" (each note escaped)."""
    lines = [f"- {run}: {markdown_text(note)}" for run, note in _notes(info)]
    return ["Notes of the runs:", ""] + lines + [""] if lines else []


__all__ = ["NUMERIC_KEYS", "cell_problem", "load_cells", "load_cells_checked", "read_cell",
           "expected_grid", "cell_key", "grid_status", "grid_status_text", "missing_md",
           "problems_md", "PER_CELL", "METHOD_KEYS", "mixed_settings", "mixed_text", "mixed_md",
           "device_label", "devices_text", "machines_text", "side_by_side_text", "variants_text",
           "input_warnings", "INPUT_WARNINGS_INTRO", "load_sweep", "run_notes",
           "run_notes_md", "wall_text"]
