"""Interactive HTML reports: ``index.html`` for every ``dbench run`` and for ``dbench report``.

A page is a self-contained folder that works from ``file://`` with no server and no network:
``index.html``, ``viewer/viewer.js`` and ``viewer/viewer.css`` (plain JavaScript and CSS
shipped with dbench) and ``viewer/data.js`` (``window.DBENCH = {...}``; a script file because
browsers refuse ``fetch`` of local files). Images travel as float data: little-endian half
floats (numpy float16), byte planes split and deflated, base64 (:func:`encode_half`), so the page tone-maps them itself at any exposure with the
report's LDR tone map (``clip(x·2^ev, 0, 1)``, then the sRGB curve; dbench.metrics.tonemap).
Values beyond the half-float range (±65504) are clipped and NaN shows as 0.

The viewer (viewer.js): number keys, arrows or clicks switch between the noisy input, each
method and the reference; wheel zoom and drag pan act on every image at once (the thumbnails
show the same window); a split view compares the shown image with any other (shift-drag or the
slider moves the split); relative- and absolute-error maps against the reference; an exposure
control in half stops; the window where the methods go most wrong (report.zoom_window) is
shown first. Sequences get a frame player and transient videos a time-bin slider. Tables sort
by any column; the best entry of each column and those tied with it are bold, methods worse
than the noisy input are flagged.
"""
from __future__ import annotations

import base64
import html
import json
import shutil
import zlib
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import pandas as pd

from .. import io
from . import headline, verdicts
from .cells import INPUT_WARNINGS_INTRO, input_warnings

ASSETS = Path(__file__).with_name("viewer")
HALF_MAX = 65504.0


def encode_half(image: np.ndarray) -> str:
    """(H, W, 3) linear radiance → base64 of zlib(low bytes, then high bytes of the
    little-endian float16 values) (NaN → 0, clipped to the half-float range). Splitting the
    bytes into two planes makes the stream about 40 % smaller than the halves themselves."""
    a = np.nan_to_num(np.asarray(image, np.float32), nan=0.0, posinf=HALF_MAX,
                      neginf=-HALF_MAX)
    a = np.ascontiguousarray(np.clip(a, -HALF_MAX, HALF_MAX).astype("<f2"))
    planes = a.view(np.uint8).reshape(-1, 2)
    packed = planes[:, 0].tobytes() + planes[:, 1].tobytes()
    return base64.b64encode(zlib.compress(packed, 6)).decode("ascii")


def decode_half(text: str, shape: tuple[int, ...]) -> np.ndarray:
    """The inverse of :func:`encode_half` (what the page computes), float32 of ``shape``."""
    packed = np.frombuffer(zlib.decompress(base64.b64decode(text)), np.uint8)
    n = packed.size // 2
    halves = (packed[:n].astype(np.uint16) | (packed[n:].astype(np.uint16) << 8))
    return halves.view("<f2").astype(np.float32).reshape(shape)


def image_entry(label: str, role: str, frames: Sequence[np.ndarray]) -> dict[str, Any]:
    """One image of the viewer: ``role`` is ``input``, ``method`` or ``reference``; ``frames``
    one (H, W, 3) array per frame or time bin (one for a steady image)."""
    return {"label": label, "role": role, "frames": [encode_half(f) for f in frames]}


def metrics_table(d: pd.DataFrame, columns: Sequence[str],
                  rank_by: str = "relmse") -> dict[str, Any]:
    """A sortable table for the viewer from a cells frame (dbench.report.tables.cells_frame):
    raw values for sorting, ``mean ± ci`` text, the best entry of each column and those whose
    interval overlaps it, and the rows worse than the noisy input (flagged) with the words,
    ranked by ``rank_by`` as the run's report is."""
    cols = [c for c in columns if c in d.columns and d[c].notna().any()]
    best = {c: verdicts.marked(d, c, exclude=("noisy",) if c == "time_s" else ()) for c in cols}
    # the report's words (dbench/report/headline.py) over the report's headline metrics
    words = headline.verdict_words(d, [c for c in cols if c in verdicts.HEADLINE], rank_by)
    flags = {lab: w for lab, w in words.items() if w.startswith("worse")}
    rows, text, flagged = [], [], []
    bold: dict[int, list[int]] = {j + 1: [] for j in range(len(cols))}
    for i, (_, r) in enumerate(d.iterrows()):
        label = str(r["method"])
        values = [float(r[c]) if np.isfinite(verdicts.num(r[c])) else None for c in cols]
        verdict = words.get(label, "")
        rows.append([label, *values, verdict])
        text.append([label] + [verdicts.fmt_value(verdicts.num(r[c]), verdicts.half_width(r, c))
                               for c in cols] + [verdict])
        for j, c in enumerate(cols):
            if label in best[c]:
                bold[j + 1].append(i)
        if label in flags:
            flagged.append(i)
    return {"columns": ["method", *cols, "verdict"], "rows": rows, "text": text,
            "best": {str(k): v for k, v in bold.items()}, "flagged": flagged}


def _kv_table(items: dict[str, Any]) -> str:
    rows = "".join(f"<tr><td>{html.escape(str(k))}</td><td>{html.escape(str(v))}</td></tr>"
                   for k, v in items.items())
    return f'<table class="kv">{rows}</table>'


VIEWER_HTML = """
<div id="thumbs"></div>
<div id="viewer">
  <canvas id="main"></canvas>
  <div id="controls">
    <div class="row"><label>exposure <input id="exposure" type="range" min="-10" max="10"
      step="0.5"> <span id="exposure-value"></span></label></div>
    <div class="row">show:
      <label><input type="radio" name="mode" value="image" checked> image</label>
      <label><input type="radio" name="mode" value="relative"> relative error
        |x−r|/(|r|+0.01)</label>
      <label><input type="radio" name="mode" value="absolute"> absolute error |x−r|</label>
    </div>
    <div class="row"><label><input id="split" type="checkbox"> split with
      <select id="other"></select></label>
      <label>split at <input id="split-at" type="range" min="0" max="1" step="0.01"
        value="0.5"></label></div>
    <div class="row"><button id="zoomwin">worst window</button> <button id="reset">whole
      image</button></div>
    <div id="player" class="row" hidden><button id="play">play</button>
      <input id="frame" type="range" min="0" value="0" step="1"> <span id="frame-label"></span>
    </div>
    <div id="status"></div>
    <p class="note">Keys: <kbd>1</kbd>–<kbd>9</kbd> or <kbd>←</kbd> <kbd>→</kbd> switch images,
      <kbd>+</kbd> <kbd>−</kbd> exposure, wheel zoom, drag pan, <kbd>z</kbd> worst window,
      <kbd>0</kbd> whole image, shift-drag moves the split; sequences: <kbd>space</kbd> play,
      <kbd>,</kbd> <kbd>.</kbd> step.</p>
  </div>
</div>
"""


def write_page(out: str | Path, *, title: str, data: dict[str, Any], sections: Sequence[str],
               viewer: bool = True) -> Path:
    """Write ``out/index.html`` with its ``viewer/`` folder (assets and ``data.js``).

    ``data`` is ``window.DBENCH``: ``width``, ``height``, ``ev``, ``images`` (image_entry),
    ``frame_labels`` (sequences and videos, else None), ``zoom`` ({x0, y0, side} or None),
    ``tables`` (metrics_table); ``sections`` are HTML fragments placed below the viewer (a
    ``<div data-table="k">`` is filled with ``tables[k]``)."""
    out = Path(out)
    folder = out / "viewer"
    folder.mkdir(parents=True, exist_ok=True)
    for name in ("viewer.js", "viewer.css"):
        with io.atomic_path(folder / name) as tmp:
            shutil.copyfile(ASSETS / name, tmp)
    io.write_text(folder / "data.js", "window.DBENCH = " + json.dumps(data, separators=(",", ":"))
                  + ";\n")
    body = [f"<h1>{html.escape(title)}</h1>", VIEWER_HTML if viewer else "", *sections]
    scripts = '<script src="viewer/data.js"></script>\n<script src="viewer/viewer.js"></script>'
    page = ("<!doctype html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<title>{html.escape(title)}</title>"
            '<link rel="stylesheet" href="viewer/viewer.css"></head>\n<body>\n'
            + "\n".join(body) + "\n" + scripts + "\n</body></html>\n")
    io.write_text(out / "index.html", page)
    return out / "index.html"


def run_page(out: str | Path, *, title: str, frame: Any, outputs: Sequence[tuple[str, Any]],
             table: pd.DataFrame, columns: Sequence[str], settings: dict[str, Any],
             machine: dict[str, Any], skipped: dict[str, str], ev: float = 0.0,
             plots: Sequence[tuple[str, str]] = (), rank_by: str = "relmse",
             failed: dict[str, str] | None = None) -> Path:
    """The page of one ``dbench run`` (steady image, sequence or transient video).

    ``frame``: the run's first-seed Frame, Sequence or TransientFrame; ``outputs``: (label,
    output) with an (H, W, 3) image, a SequenceResult with kept outputs, or an (H, W, T, 3)
    video; ``table``: the run's cells frame; ``plots``: (title, file name in ``out``);
    ``failed``: label → error of the methods that failed, listed as report.md's "Failed"
    section lists them (README.md, "Usage")."""
    from ..metrics import DEFINITIONS
    from .run_report import zoom_window

    kind = getattr(frame, "kind", "steady")
    labels = None
    if kind == "sequence":
        frames = list(frame)
        noisy = [f.color for f in frames]
        reference = [f.reference for f in frames]
        outs = [(lab, list(o.outputs)) for lab, o in outputs if lab != "noisy"]
        labels = [f"frame {i}" for i in range(len(frames))]
    elif kind == "transient":
        t = frame.color.shape[2]
        noisy = [frame.color[:, :, k] for k in range(t)]
        reference = [frame.reference[:, :, k] for k in range(t)]
        outs = [(lab, [o[:, :, k] for k in range(t)]) for lab, o in outputs if lab != "noisy"]
        meta = frame.meta
        start, width = meta.get("start_opl"), meta.get("bin_width_opl")
        labels = [f"bin {k}" + (f" ({start + (k + 0.5) * width:.2f} m)" if start is not None
                                and width is not None else "") for k in range(t)]
    else:
        noisy, reference = [frame.color], [frame.reference]
        outs = [(lab, [o]) for lab, o in outputs if lab != "noisy"]
    images = ([image_entry("noisy", "input", noisy)]
              + [image_entry(lab, "method", fr) for lab, fr in outs]
              + [image_entry("reference", "reference", reference)])
    # the zoom window and the first frame shown: where the methods go most wrong (the last
    # frame of a sequence, after the warm-up; the brightest bin of a video)
    show = len(reference) - 1 if kind == "sequence" else (
        int(np.argmax([np.nanmean(r) for r in reference])) if kind == "transient" else 0)
    y0, x0, side = zoom_window(reference[show], [fr[show] for _, fr in outs], ev)
    h, w = reference[0].shape[:2]
    data = {"width": int(w), "height": int(h), "ev": float(ev), "images": images,
            "frame_labels": labels, "start_frame": show,
            "zoom": {"x0": int(x0), "y0": int(y0), "side": int(side)},
            "tables": [metrics_table(table, columns, rank_by)]}
    d = table
    rank = verdicts.ranking_metric(d, rank_by) if len(d) else rank_by
    # what report.md says above its table: the ranking, the kind of interval (one seed: a
    # block bootstrap, or none), the reference's spp and estimated error
    head = (f"Ranking by {verdicts.ranking_line(d, rank, rank_by)}. "
            f"{verdicts.ci_kind_text(d).capitalize()}; {verdicts.reference_text(d)}."
            if len(d) else "No method finished.")
    sections = ["<h2>Metrics</h2>", f'<p class="note">{html.escape(head)}</p>',
                '<div data-table="0"></div>',
                '<p class="note">Mean ± 95 % half-width; bold: the best entry of a column and '
                "every entry tied with it (paired over common seeds, else overlapping "
                "intervals; the noisy input is not a candidate for the fastest time_s); a row in red is worse than the noisy input on at least one "
                "headline metric, as its verdict says (which metrics, by how much, and which "
                "losses the intervals cannot tell from none). Click a column to sort.</p>"]
    if failed:
        # a failed method has no row and no image: without this the page would not say it ran
        sections += ["<h2>Failed</h2>", '<p class="note">These methods raised an error or '
                     "broke the method contract; they have no row above, and the run exits "
                     "with code 4.</p>", _kv_table(failed)]
    if skipped:
        sections += ["<h2>Skipped</h2>", _kv_table(skipped)]
    if plots:
        sections += ["<h2>Figures</h2>", '<div class="plots">' + "".join(
            f'<img src="{html.escape(src)}" alt="{html.escape(t)}" title="{html.escape(t)}">'
            for t, src in plots) + "</div>"]
    sections += ["<h2>Settings</h2>", _kv_table(settings),
                 "<h2>Metric definitions</h2>", _kv_table(DEFINITIONS),
                 "<h2>Machine</h2>", _kv_table(machine),
                 '<p class="note">Images are stored as half floats and tone-mapped in the page '
                 "(clip(x·2^ev, 0, 1), then sRGB), the report's LDR tone map.</p>"]
    return write_page(out, title=title, data=data, sections=sections)


def grid_table(df: pd.DataFrame, metric: str) -> dict[str, Any]:
    """The scene × method × spp grid of one sweep for the viewer's table: one row per (scene,
    method), one column per spp, ``metric`` as mean ± interval (raw means for sorting); rows
    worse than the noisy input at the headline spp are flagged."""
    from .tables import NO_VALUE, NONFINITE

    spps = sorted(int(v) for v in df.spp.unique())
    rows, text, flagged = [], [], []
    head = verdicts.headline_spp(spps)
    for (scene, method), g in df.groupby(["scene", "method"], sort=True):
        by_spp = {int(r.spp): r for r in g.itertuples()}
        values, words = [], []
        for spp in spps:
            r = by_spp.get(spp)
            v = verdicts.num(getattr(r, metric)) if r is not None else float("nan")
            ci = verdicts.num(getattr(r, metric + "_ci", float("nan"))) if r is not None \
                else float("nan")
            values.append(v if np.isfinite(v) else None)
            # a cell without a value is said as the README's convergence tables say it
            words.append(verdicts.fmt_value(v, ci) if np.isfinite(v) else "" if r is None else
                         NONFINITE if verdicts.num(getattr(r, "n_nonfinite", 0)) > 0
                         else NO_VALUE)
        at = df[(df.scene == scene) & (df.spp == head)]
        if method in headline.worse_than_noisy(at, [metric]):
            flagged.append(len(rows))
        rows.append([scene, method, *values])
        text.append([scene, method, *words])
    return {"columns": ["scene", "method", *[f"{s} spp" for s in spps]], "rows": rows,
            "text": text, "best": {}, "flagged": flagged}


def input_warnings_html(cells: Sequence[dict]) -> list[str]:
    """The sweep's "Input warnings" as its README states them
    (:func:`dbench.report.cells.input_warnings`: once per scene and warning, with the spp where
    it holds at some only), as HTML text: a scene is named as its file is, a warning quotes
    file names; nothing where the inputs said nothing."""
    return _listed_html("Input warnings", INPUT_WARNINGS_INTRO, input_warnings(cells))


def nondeterministic_html(cells: Sequence[dict]) -> list[str]:
    """The sweep's "Not reproducible" cells as its README states them
    (:func:`dbench.report.headline.nondeterministic_lines`), as HTML; nothing where none."""
    return _listed_html("Not reproducible", headline.NONDETERMINISTIC_INTRO,
                        headline.nondeterministic_lines(cells))


def _listed_html(title: str, intro: str, said: list[str]) -> list[str]:
    """An ``<h3>`` ``title``, ``intro`` (with ``{run}``, the command as code) and ``said`` as a
    list, each line escaped; nothing where ``said`` is empty."""
    if not said:
        return []
    return [f"<h3>{title}</h3>", '<p class="note">' + intro.format(
        run="<code>dbench run</code>") + "</p>", '<ul class="note">' + "".join(
            f"<li>{html.escape(line)}</li>" for line in said) + "</ul>"]


def sweep_page(results: str | Path, sweeps: Sequence[tuple], rank_by: str = "relmse") -> Path:
    """``results/index.html``: for every sweep, given as (folder, its cells) or (folder, its
    cells, its settings line as the README gives it: reference spp and error, variant,
    intervals, skipped cells, then its runs' notes, :func:`dbench.report.cells.run_notes`), what its inputs said of themselves (:func:`input_warnings_html`),
    its figures (convergence and error against time, static PNGs, drawn first by
    :func:`dbench.report.publish.build_readme`) and the sortable scene × method × spp grid of
    ``rank_by`` with intervals; rows worse than the noisy input at the headline spp in red, as
    the page says. Sweeps keep numbers, not images: the images of a
    cell are in the folder of the ``dbench run`` that reproduces it (``dbench run --method M
    --scene S --spp N``)."""
    from .tables import cells_frame

    results = Path(results)
    links = ['<a href="README.md">README.md</a>'] + (
        ['<a href="table_3_1.md">Table 3.1</a>'] if (results / "table_3_1.md").is_file() else [])
    tables, sections = [], ['<p class="note">The numbers behind README.md in this folder, '
                            "sortable (click a column). Sweeps keep numbers, not images: "
                            "`dbench run` pages hold the images (viewer with zoom, exposure "
                            "and error maps).</p>", "<p>" + " · ".join(links) + "</p>"]
    for sweep_dir, cells, *summary in sweeps:
        df = cells_frame(cells)
        if not len(df):
            continue
        rel = Path(sweep_dir).relative_to(results).as_posix()
        metric = verdicts.ranking_metric(df, rank_by)
        head = verdicts.headline_spp(df.spp.unique())
        sections += [f"<h2>Sweep {html.escape(rel)}</h2>"]
        sections += [f'<p class="note">{html.escape(str(line))}</p>' for line in summary]
        sections += input_warnings_html(cells) + nondeterministic_html(cells)
        sections += [f'<p class="note">{html.escape(metric)}: mean ± 95 % half-width, rows '
                     f"scene/method, columns spp; a row in red is worse than the noisy input "
                     f"on {html.escape(metric)} at {head} spp (the README's headline "
                     "spp).</p>", f'<div data-table="{len(tables)}"></div>']
        tables.append(grid_table(df, metric))
        figures = sorted(Path(sweep_dir).glob("*.png"))
        if figures:
            sections.append('<div class="plots">' + "".join(
                f'<img src="{html.escape(p.relative_to(results).as_posix())}" '
                f'alt="{html.escape(p.stem)}" title="{html.escape(p.stem)}">' for p in figures)
                + "</div>")
    return write_page(results, title="dbench results", data={"tables": tables},
                      sections=sections, viewer=False)


__all__ = ["encode_half", "decode_half", "image_entry", "metrics_table", "run_page", "write_page",
           "grid_table", "input_warnings_html", "nondeterministic_html", "sweep_page"]
