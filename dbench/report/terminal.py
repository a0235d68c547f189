"""What ``dbench run`` and ``dbench sweep`` print: the headline a researcher reads first
(README.md, "Usage"), in plain text at most :data:`WIDTH` columns wide.

The rows, their order, the ranking sentence and the verdict words are those of ``report.md``
and the README (dbench/report/headline.py, dbench/report/verdicts.py); this module only lays them
out for a terminal. Skipped methods are grouped by the kind of their reason (one line, not one
per method).
"""
from __future__ import annotations

import re
import textwrap
from typing import Any, Iterable, Mapping, Sequence

import pandas as pd

from . import headline
from .verdicts import (NOISY, ci_kind_text, finite, fmt_value, half_width, headline_spp, num,
                       ranking_line, ranking_metric, ref_warnings_md, reference_text)

WIDTH = 100

_WORKS_ON = re.compile(r"works on \[([^\]]*)\], not on (\w+) data")
_COUNTERPARTS = re.compile(r"; on (\w+) data: (.*)$")
_HINT = re.compile(r"; (--param .*)$")
_NEEDS = re.compile(r"needs \[([^\]]*)\], which the scene cannot provide")


def skip_kind(reason: str) -> str:
    """The kind of a skip reason (dbench/denoiser.py ``applies_to``): ``sequence only``,
    ``needs albedo, normal``; any other reason as it stands."""
    m = _WORKS_ON.search(reason)
    if m:
        kinds = [k.strip().strip("'\"") for k in m.group(1).split(",") if k.strip()]
        return " or ".join(kinds) + " only"
    m = _NEEDS.search(reason)
    if m:
        return "needs " + ", ".join(k.strip().strip("'\"") for k in m.group(1).split(","))
    return reason.strip()


def skipped_line(skipped: Mapping[str, str] | Iterable[tuple[str, str]]) -> str:
    """``skipped: bmfr, svgf (sequence only); gauss3d (transient only)``: the methods grouped by
    :func:`skip_kind`, in the order given, with the methods that do their work on the data at
    hand where a reason names them (``jbf, oidn (steady only; on transient data: jbf-bins,
    oidn-bins)``, dbench/denoiser.py ``counterparts``); "" when nothing was skipped."""
    pairs = skipped.items() if isinstance(skipped, Mapping) else skipped
    groups: dict[str, tuple[list[str], dict[str, list[str]]]] = {}
    for label, why in pairs:
        names, others = groups.setdefault(skip_kind(str(why)), ([], {}))
        if label not in names:
            names.append(str(label))
        m = _COUNTERPARTS.search(str(why))
        if m:
            seen = others.setdefault(m.group(1), [])
            seen += [o for o in (x.strip() for x in m.group(2).split(",")) if o not in seen]
        hint = _HINT.search(str(why))
        if hint:  # a setting that would run it (oidn's features=none on colour alone)
            others.setdefault("", []).append(hint.group(1))
    if not groups:
        return ""

    def notes(others: dict[str, list[str]]) -> str:
        return "".join(f"; on {kind} data: {', '.join(os_)}" if kind else
                       "".join(f"; {h}" for h in os_) for kind, os_ in others.items())
    text = "skipped: " + "; ".join(f"{', '.join(ms)} ({k}{notes(others)})"
                                   for k, (ms, others) in groups.items())
    return textwrap.fill(text, WIDTH, subsequent_indent="  ", break_on_hyphens=False)


def time_text(seconds: Any, device: str | None = None) -> str:
    """``1.84 ms cpu``: the median denoise time with where it ran."""
    s = num(seconds)
    t = ("—" if not finite(s) else f"{s:.3g} s" if s >= 1 else
         f"{s * 1e3:.3g} ms" if s >= 1e-3 else f"{s * 1e6:.3g} µs")
    return f"{t} {device}" if device else t


def _metric_columns(d: pd.DataFrame, rank_by: str) -> list[str]:
    surface = [] if rank_by.endswith(headline.SURFACE) else [rank_by + headline.SURFACE]
    cols = [rank_by, *surface, "rmse", "rmse_surface"]
    return [c for c in dict.fromkeys(cols) if c in d.columns and d[c].map(finite).any()]


def _layout(rows: list[list[str]], header: list[str], right: Sequence[bool]) -> list[str]:
    widths = [max(len(r[j]) for r in [header, *rows]) for j in range(len(header))]
    return ["  ".join(c.rjust(w) if ra else c.ljust(w) for c, w, ra in zip(r, widths, right))
            .rstrip() for r in [header, *rows]]


def headline_table(d: pd.DataFrame, rank_by: str, devices: Mapping[str, str] | None = None,
                   max_label: int = 24) -> list[str]:
    """The ranked rows: place (tied rows share it), method, ``mean ± interval`` of the ranking
    metric, its surface variant, rmse and rmse_surface, and the time with its device."""
    cols = _metric_columns(d, rank_by)
    by_label = {str(r["method"]): r for _, r in d.iterrows()}
    ranked = headline.ranked_labels(d, rank_by)
    devices = devices or {}

    def short(label: str) -> str:
        return label if len(label) <= max_label else label[:max_label - 1] + "…"

    while True:
        header = ["#", "method", *cols, "time"]
        rows = [[str(p) if p is not None else "—", short(lab),
                 *(fmt_value(num(by_label[lab][c]), half_width(by_label[lab], c), ".3g")
                   for c in cols),
                 time_text(by_label[lab].get("time_s"), devices.get(lab))]
                for p, lab in ranked]
        lines = _layout(rows, header, [True, False, *([False] * len(cols)), False])
        # too wide: the whole-image rmse goes first, then the ranking metric's surface form
        drop = [c for c in ("rmse", rank_by + headline.SURFACE) if c in cols[1:]]
        if max(map(len, lines)) <= WIDTH or not drop:
            left_out = [c for c in _metric_columns(d, rank_by) if c not in cols]
            if left_out:  # said, not silently missing (report.md has every column)
                lines += _wrap(f"(not shown, to fit {WIDTH} columns: {', '.join(left_out)}; "
                               f"report.md has them)")
            return lines
        cols.remove(drop[0])


def failed_rows(failed: Mapping[str, str]) -> list[str]:
    """``✗  label  failed: why`` under the ranked rows for each method that failed (its error
    row; exit code 4: README.md, "Usage"), cut to :data:`WIDTH`."""
    out = []
    for label, why in failed.items():
        line = f"✗  {label}  failed: {' '.join(str(why).split())}"
        out.append(line if len(line) <= WIDTH else line[:WIDTH - 1] + "…")
    return out


def verdict_lines(d: pd.DataFrame, columns: Sequence[str], rank_by: str) -> list[str]:
    """``  jbf: worse than noisy on …`` for every row with something to say (the report's
    words, :func:`dbench.report.headline.verdict_words`), wrapped at :data:`WIDTH`."""
    words = headline.verdict_words(d, columns, rank_by)
    out = []
    for _, lab in headline.ranked_labels(d, rank_by):
        if words.get(lab) and lab != NOISY:
            out += textwrap.wrap(f"{lab}: {words[lab]}", WIDTH, initial_indent="  ",
                                 subsequent_indent="      ", break_on_hyphens=False)
    return out


def ref_warning_lines(d: pd.DataFrame, indent: str = "") -> list[str]:
    """report.md's "Reference noise" lines (:func:`dbench.report.verdicts.ref_warnings_md`)
    for the terminal, where most readers look: ``warning: cornell, 64 spp: …``."""
    return [line for w in ref_warnings_md(d, name=str)
            for line in _wrap("warning: " + w.removeprefix("- ⚠ ").replace("`", ""), indent)]


def _wrap(text: str, indent: str = "") -> list[str]:
    return textwrap.wrap(text, WIDTH, initial_indent=indent, subsequent_indent=indent + "  ",
                         break_on_hyphens=False)


def run_summary(d: pd.DataFrame, settings: Mapping[str, Any], rank_by: str,
                columns: Sequence[str], devices: Mapping[str, str] | None = None,
                asked: str | None = None, failed: Mapping[str, str] | None = None
                ) -> list[str]:
    """The headline of one run: what was run, the reference, the ranked table with intervals,
    the ranking sentence and the verdicts of ``report.md``. ``d``: the report's cells frame
    (dbench/report/run_report.py ``_run_frame``); ``columns``: the report's headline columns."""
    from ..resolution import size_text

    seeds = str(settings.get("seeds", ""))
    # a folder's is a sentence ("one render per spp, from the files"), not a list of seeds
    n_seeds = len(seeds.split(", ")) if re.fullmatch(r"\d+(, \d+)*", seeds) else 1
    lines = _wrap(f"{settings.get('scene')} at {settings.get('spp')} spp, "
                  f"{size_text(settings.get('res'))} px, {n_seeds} seed"
                  f"{'s' if n_seeds != 1 else ''}; device {settings.get('device', 'cpu')}")
    lines += _wrap(f"reference: {settings.get('ref_spp') or 'unknown'} spp, estimated RMSE "
                   f"{_ref_error(settings.get('reference RMSE (estimated)'))}")
    for line in scene_file_lines(settings):
        lines += _wrap(line, "  ")
    if not len(d):
        return lines + ["(no method finished)"]
    lines += _wrap(f"{ci_kind_text(d).capitalize()}; entries are mean ± 95 % half-width.")
    lines += [""] + headline_table(d, rank_by, devices) + failed_rows(failed or {}) + [""]
    lines += _wrap(f"ranking by {ranking_line(d, rank_by, asked)}")
    verdicts = verdict_lines(d, columns, rank_by)
    if verdicts:
        lines += ["verdicts (size of the loss: mean / noisy's; PSNR, SSIM: the difference):"] \
            + verdicts
    return lines + ref_warning_lines(d)


#: The settings of a scene file's render that may differ from the file
#: (dbench/datasets/scene_files/fidelity.py report_lines: "X (file: Y) — why" when they do).
SCENE_FILE_SETTINGS = ("integrator", "filter", "sampler", "film")


def scene_file_lines(settings: Mapping[str, Any]) -> list[str]:
    """What the render changed from a scene file and the ``$parameters`` it was given, as the
    report states them (docs/formats.md §3; README.md, "Your scene, your renders, any size"):
    nothing for a scene rendered as its file says."""
    changed = [f"{k} {settings[k]}" for k in SCENE_FILE_SETTINGS
               if "(file:" in str(settings.get(k, ""))]
    if settings.get("conversions"):
        changed.append(f"conversions: {settings['conversions']}")
    lines = [f"scene file changed: {c}" for c in changed]
    if settings.get("scene parameters"):
        lines.append(f"scene parameters: {settings['scene parameters']}")
    return lines


def _ref_error(value: Any) -> str:
    """The reference's estimated RMSE as the settings hold it: a number, "value (source)" or
    "unknown (why)"."""
    if finite(value):
        return f"{float(value):.3g}"
    text = str(value) if value is not None else ""
    number, _, source = text.partition(" (")
    if source and re.fullmatch(r"[0-9.eE+-]+", number):  # "0.006342895671915049 (variance …)"
        try:
            return f"{float(number):.3g} ({source}"
        except ValueError:
            pass
    return text if text.startswith("unknown") else (text or "unknown")


def sweep_summary(cells: Sequence[dict], rank_by: str = "relmse",
                  columns: Sequence[str] = (), skips: bool = True,
                  beside: Sequence[dict] | None = None) -> list[str]:
    """Per scene at its headline spp (the README's, :func:`headline_spp`): the ranking sentence
    and the verdicts, a warning where cells computed with different settings stand side by side
    among ``beside`` (default ``cells``: the folder's cells of the same labels and scenes, at
    any spp; :func:`dbench.report.cells.mixed_settings`), a warning for each doubt the cells
    recorded of their inputs (:func:`dbench.report.cells.input_warnings`) and of their methods'
    calls (:func:`dbench.report.headline.nondeterministic_lines`), then (``skips``)
    the skipped methods grouped by reason kind, one line."""
    from .tables import cells_frame

    df = cells_frame(list(cells))
    lines: list[str] = []
    for scene, g in (df.groupby("scene", sort=True) if len(df) else []):
        spp = headline_spp(g["spp"].unique())
        at = g[g["spp"] == spp]
        rank = ranking_metric(at, rank_by)
        cols = columns or [c for c in headline.HEADLINE if c in at.columns]
        lines += _wrap(f"{scene} at {spp} spp ({reference_text(at)}): "
                       f"ranking by {ranking_line(at, rank, rank_by)}")
        lines += verdict_lines(at, cols, rank) + ref_warning_lines(at, "  ")
    # a --rerun over part of the grid leaves the rest as it was: never a silent mix
    from .cells import input_warnings, mixed_settings, mixed_text, side_by_side_text
    mixed = mixed_text(mixed_settings(cells if beside is None else beside),
                       'dbench report lists them under "Mixed settings"', name=str)
    lines += _wrap("warning: " + mixed.removeprefix("⚠ ")) if mixed else []
    # times measured beside other cells (dbench sweep --workers N, Ray) include contention
    for said in side_by_side_text(cells):
        lines += _wrap(f"warning: {said}")
    # what the inputs said of themselves, as `dbench run` prints it (dbench/run/inputs.py)
    for said in input_warnings(cells):
        lines += _wrap(f"warning: {said}")
    # calls on one input that differed, at any spp, as `dbench run` prints it (harness.py)
    for said in headline.nondeterministic_lines(cells):
        lines += _wrap(f"warning: {said}")
    skipped = [(str(c.get("method")), str(c.get("reason", "")))
               for c in cells if isinstance(c, dict) and c.get("status") == "skipped"]
    line = skipped_line(skipped) if skips else ""
    return lines + ([line] if line else [])


__all__ = ["WIDTH", "failed_rows", "skip_kind", "skipped_line", "time_text", "headline_table",
           "verdict_lines", "run_summary", "sweep_summary", "scene_file_lines"]
