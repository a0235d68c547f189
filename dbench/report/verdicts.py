"""Verdicts from sweep cells (docs/judging.md): intervals, best and tied methods, rankings,
methods worse than the noisy input and the reference's own noise (the grid of cells: expected,
missing and mixed, in dbench/report/cells.py, imported here for the callers).

Everything here reads a frame of :func:`dbench.report.tables.cells_frame` (one row per cell,
``<metric>`` and ``<metric>_ci`` columns) and returns Markdown lines or small frames; nothing
is timed, rendered or read from a clock, so the same cells give the same text.

Conventions:

* an entry is ``mean ± half-width`` of the cell's 95 % interval (``ci_kind`` says which kind);
  ``time_s`` is the median denoise time ± half its interquartile range (a spread, not a CI);
* two methods are *tied* when the 95 % t-interval of their difference seed by seed includes 0
  (a *paired* comparison, docs/judging.md §3: both ran on the same noisy renders, so the
  difference has a far smaller interval than either method's own), when their cells share at
  least two seeds; otherwise when their intervals overlap, |m₁ − m₂| ≤ h₁ + h₂; a missing
  interval (one seed on an image too small for the block bootstrap, README.md "Metrics")
  cannot tell two means apart, so it ties ("no interval") and is shown as ``± n/a``; the best
  entry of a column and every entry tied with it are marked in bold;
* lower is better except where the metric's record says higher (dbench/metrics/records.py:
  PSNR, SSIM and their surface forms, tPSNR, ColorVideoVDP's JOD).

The ranked tables and the verdict words built on these (report.md, the README, the terminal)
are in dbench/report/headline.py.
"""
from __future__ import annotations

import math
from typing import Any, Callable, Iterable

import numpy as np
import pandas as pd

from ..metrics import records
from .cells import expected_grid, grid_status, grid_status_text, missing_md
from .formats import markdown_text

#: How a text names a method or scene: as it is (the terminal, the viewer, which escapes HTML)
#: or escaped for Markdown (:func:`dbench.report.formats.markdown_text`).
Namer = Callable[[Any], str]

#: Metric columns of a cell (each with a ``_ci`` half-width column), from the metric records.
METRICS = records.cell_columns()
#: Every metric where a larger value is better, from the metric records.
HIGHER_IS_BETTER = records.higher_is_better_names()
#: The time column every headline table ends with (not a metric: no record).
TIME = "time_s"


def headline_columns(run: str) -> tuple[str, ...]:
    """Columns of the headline table of a ``run`` ("steady", "sequence", "transient"): the
    metrics whose records name that run, then :data:`TIME`."""
    return records.headline(run) + (TIME,)


#: Columns of the headline table.
HEADLINE = headline_columns("steady")
#: Warn when the reference's MSE exceeds this share of a method's MSE.
REF_SHARE = 0.1
NOISY = "noisy"

#: The verdicts' own quantities that are not metrics: the reference's estimated error and the
#: intervals.
REF_RMSE_DEFINITION = (
    "ref_rmse = sqrt(mean v_r), the estimated RMSE of the reference itself; a warning is "
    "printed when the reference's relMSE over surface pixels, mean(v_r / (r² + ε)), exceeds "
    "0.1 · relmse_surface of a method (cells without it: ref_rmse² > 0.1 · MSE)")
CI_DEFINITION = (
    "intervals: with N > 1 seeds, Student t over seeds, mean ± t_{0.975,N−1} · s / √N "
    "(the shared reference's error is not in it; see ref_rmse); with one seed, a block "
    "bootstrap percentile interval over B × B pixel blocks (B = 16 where 16 such "
    "blocks fit, else the largest B ≥ 4 that gives 16; on smaller images no interval, "
    "shown as ± n/a); `time_s` shows the median "
    "denoise time ± half its interquartile range. Two methods tie when the t-interval "
    "of their differences seed by seed (both ran on the same noisy renders) includes "
    "0; without two common seeds, when their intervals overlap, or when either has "
    "no interval (a missing interval never makes a method better)")


def definitions() -> dict[str, str]:
    """One line per quantity the reports define, in order: every metric record's (the image
    metrics, ``surface`` for their surface forms, the judge's figures), ``ref_rmse``, the
    sequence metrics', ``ci``."""
    image = records.definitions(("image",))
    rest = {k: v for k, v in records.definitions().items() if k not in image}
    return {**image, "ref_rmse": REF_RMSE_DEFINITION, **rest, "ci": CI_DEFINITION}


#: :func:`definitions` when the package was loaded.
DEFINITIONS = definitions()


def higher_is_better(metric: str) -> bool:
    """The direction of ``metric`` from its record (unknown names, ``time_s``: lower)."""
    return records.higher_is_better(metric)


def num(v: Any) -> float:
    """A finite-or-NaN float from any cell value (None, strings, lists, bools → NaN)."""
    if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer,
                                                           np.floating)):
        return float("nan")
    return float(v)


def _finite(v: Any) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and math.isfinite(float(v))


finite = _finite


def _field(row: Any, key: str, default: Any = None) -> Any:
    """``row[key]`` of a frame row or dict, or the attribute of a record; ``default`` if absent."""
    return row.get(key, default) if hasattr(row, "get") else getattr(row, key, default)


def half_width(row: Any, metric: str) -> float:
    """The 95 % half-width of ``metric`` in ``row`` (NaN if unknown); for ``time_s`` the
    interval when one is stored, else half the interquartile range."""
    h = num(_field(row, metric + "_ci", float("nan")))
    if metric == "time_s" and not math.isfinite(h):
        h = num(_field(row, "time_s_iqr", float("nan"))) / 2
    return h


def fmt_value(mean: float, ci: float = float("nan"), fmt: str = ".4g") -> str:
    if not _finite(mean):
        return "—"
    # a missing interval is said, not dropped: a bare mean would read as exact
    return (f"{format(float(mean), fmt)} ± {float(ci):.2g}" if _finite(ci)
            else f"{format(float(mean), fmt)} ± n/a")


def overlaps(m1: float, h1: float, m2: float, h2: float) -> bool:
    """|m₁ − m₂| ≤ h₁ + h₂; True when either interval is missing (nothing tells them apart)."""
    if not (_finite(h1) and _finite(h2)):
        return True
    return abs(m1 - m2) <= h1 + h2


def seed_values(entries: Any) -> dict[int, dict[str, float]]:
    """{seed: {metric: value}} of a cell's ``per_seed`` list (finite values of
    :data:`METRICS` only; entries without an integer seed left out): what a paired comparison
    pairs. A dict already in that form is returned as it is."""
    if isinstance(entries, dict):
        return entries
    out: dict[int, dict[str, float]] = {}
    for e in entries if isinstance(entries, list) else []:
        seed = e.get("seed") if isinstance(e, dict) else None
        if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)):
            continue
        vals = {m: float(e[m]) for m in METRICS if _finite(e.get(m))}
        if vals:
            out[int(seed)] = vals
    return out


def paired_interval(row_a: Any, row_b: Any, metric: str) -> tuple[float, float] | None:
    """(mean, 95 % half-width) of ``metric`` of ``row_a`` minus ``row_b`` seed by seed over the
    seeds both cells hold (their ``per_seed``, :func:`dbench.report.tables.cells_frame`); None
    with fewer than two such seeds."""
    from ..metrics.judge import t_interval

    a, b = seed_values(_field(row_a, "per_seed")), seed_values(_field(row_b, "per_seed"))
    diffs = [a[k][metric] - b[k][metric] for k in sorted(set(a) & set(b))
             if metric in a[k] and metric in b[k]]
    if len(diffs) < 2:
        return None
    mean, half = t_interval(diffs)
    return (mean, half) if math.isfinite(mean) and math.isfinite(half) else None


def tie(row_a: Any, row_b: Any, metric: str) -> str | None:
    """How two rows tie on ``metric``: "paired" (the paired interval includes 0), "overlap"
    (no common seeds, and the intervals overlap), "none" (no common seeds, and one of them has
    no interval: nothing says which is ahead), or None (one is ahead)."""
    paired = paired_interval(row_a, row_b, metric)
    if paired is not None:
        return "paired" if abs(paired[0]) <= paired[1] else None
    ha, hb = half_width(row_a, metric), half_width(row_b, metric)
    if not (_finite(ha) and _finite(hb)):
        return "none"
    return "overlap" if overlaps(num(_field(row_a, metric)), ha,
                                 num(_field(row_b, metric)), hb) else None


TIE_WORDS = {"overlap": "intervals overlap", "paired": "paired difference includes 0",
              "none": "no interval"}


def _entries(d: pd.DataFrame, metric: str, exclude: Iterable[str] = ()
             ) -> list[tuple[float, str, Any]]:
    """(mean, label, row) of the rows with a finite value, best first."""
    if metric not in d.columns:
        return []
    skip = set(exclude)
    out = [(float(r[metric]), str(r["method"]), r)
           for _, r in d.iterrows() if _finite(r[metric]) and r["method"] not in skip]
    sign = -1.0 if higher_is_better(metric) else 1.0
    return sorted(out, key=lambda e: (sign * e[0], e[1]))


def marked(d: pd.DataFrame, metric: str, exclude: Iterable[str] = ()) -> set[str]:
    """The best label of ``metric`` and every label tied with it (:func:`tie`)."""
    e = _entries(d, metric, exclude)
    if not e:
        return set()
    best = e[0][2]
    return {lab for _, lab, r in e if lab == e[0][1] or tie(r, best, metric)}


def _rank(d: pd.DataFrame, metric: str) -> list[tuple[list[str], set[str]]]:
    """Tied groups best first, each with how its members tie with its leader."""
    groups: list[tuple[list[str], set[str]]] = []
    leader = None
    for _, lab, r in _entries(d, metric):
        how = tie(r, leader, metric) if leader is not None else None
        if how:
            groups[-1][0].append(lab)
            groups[-1][1].add(how)
        else:
            groups.append(([lab], set()))
            leader = r
    return groups


def rank_groups(d: pd.DataFrame, metric: str) -> list[list[str]]:
    """Labels best first; consecutive labels tied with the group leader (:func:`tie`) form
    one tied group."""
    return [labels for labels, _ in _rank(d, metric)]


def ranking_metric(d: pd.DataFrame, asked: str) -> str:
    """The metric that ranks ``d``: ``asked`` where any row has a value of it, else the metric
    it is a form of (``relmse`` for ``relmse_unbiased`` or ``relmse_surface``) where that has
    one, else ``rmse``; :func:`ranking_line` with ``asked`` says when another one ranks."""
    def has(m: str | None) -> bool:
        return m is not None and m in d.columns and bool(d[m].map(_finite).any())

    base = getattr(records.METRICS.get(asked), "variant_of", None)
    return asked if has(asked) else base if has(base) else "rmse"


def ranking_line(d: pd.DataFrame, metric: str, asked: str | None = None,
                 name: Namer = str) -> str:
    """e.g. ``relmse (lower is better): oidn < a = b (tied: intervals overlap) < noisy``; a
    group that ties with a method of the group before it follows it with ``≤`` and says which
    (``a = b ≤ c (≤: c ties with b)``). ``asked``: the metric the user asked to rank by, named
    where it had no value and ``metric`` ranks instead; ``name`` writes each method's label
    (Markdown: :func:`dbench.report.formats.markdown_text`)."""
    if metric not in d.columns:
        return f"{metric}: not recorded in these cells"
    op, le = (" > ", "≥") if higher_is_better(metric) else (" < ", "≤")
    rows = {lab: r for _, lab, r in _entries(d, metric)}
    text, previous = "", []
    for g, how in _rank(d, metric):
        notes = ["tied: " + "; ".join(TIE_WORDS[h] for h in sorted(how))] if len(g) > 1 else []
        # ties are not transitive: a group starts where a method no longer ties with the
        # leader, yet it may tie with a member of the group before; then "<" would claim an
        # order the intervals do not show (docs/judging.md §3)
        bridge = [(a, b) for a in previous for b in g if tie(rows[a], rows[b], metric)]
        part = " = ".join(map(name, g)) + (f" ({'; '.join(notes)})" if notes else "") + "".join(
            f" ({le}: {name(b)} ties with {name(a)})" for a, b in bridge[:1])
        text = (text + (f" {le} " if bridge else op) + part) if text else part
        previous = g
    missing = [name(m) for m in sorted(str(m) for m, v in zip(d["method"], d[metric])
                                       if not _finite(v))]
    text = (f"{metric} ({'higher' if higher_is_better(metric) else 'lower'} is better): "
            + (text or "no values"))
    text += f"; no value: {', '.join(missing)}" if missing else ""
    if asked and asked != metric:
        text += f" ({asked}, asked for, has no value here, so {metric} ranks)"
    return text


def ci_kind_text(d: pd.DataFrame) -> str:
    kinds = sorted({str(k) for k in d.get("ci_kind", pd.Series(dtype=object))
                    if isinstance(k, str) and k})
    if not kinds:
        return "no confidence intervals in these cells (one render, no interval stored)"
    return "intervals: " + "; ".join(kinds)


def _cells_text(g: pd.DataFrame, all_methods: set[str], name: Namer = str) -> str:
    """``4, 16 spp`` or ``64 spp (jbf, oidn)`` for the cells of ``g``."""
    parts = []
    for spp, h in g.groupby("spp", sort=True):
        ms = sorted(set(map(str, h["method"])))
        parts.append(f"{int(spp)} spp" + ("" if set(ms) >= all_methods else
                                          f" ({', '.join(map(name, ms))})"))
    return ", ".join(parts)


def reference_text(d: pd.DataFrame, name: Namer = str) -> str:
    """The reference spp actually used by the cells of one scene (never the config's);
    ``name`` writes the methods' labels (:func:`ranking_line`)."""
    refs = d["ref_spp"].map(num) if "ref_spp" in d.columns else pd.Series(dtype=float)
    known = sorted({int(v) for v in refs if math.isfinite(v)})
    if not known:
        return "reference spp not recorded in these cells"
    if len(known) == 1 and refs.notna().all():
        text = f"reference {known[0]} spp"
    else:
        methods = set(map(str, d["method"]))
        per = [f"{v} spp for {_cells_text(d[refs == v], methods, name)}" for v in known]
        if refs.isna().any():
            per.append(f"not recorded for {_cells_text(d[refs.isna()], methods, name)}")
        text = "reference differs between cells: " + "; ".join(per)
    err = d["ref_rmse"].map(num) if "ref_rmse" in d.columns else pd.Series(dtype=float)
    err = err[np.isfinite(err)]
    if len(err):
        lo, hi = float(err.min()), float(err.max())
        text += (f", estimated reference RMSE {lo:.3g}" if lo == hi else
                 f", estimated reference RMSE {lo:.3g}–{hi:.3g}")
    else:  # said, not left out: a reader must not take the reference for exact
        text += ", estimated reference RMSE unknown"
    return text


def reference_summary(df: pd.DataFrame, name: Namer = str) -> str:
    """One phrase for a sweep header: the reference spp of every scene, from the cells;
    ``name`` writes the scenes' and methods' names (:func:`ranking_line`)."""
    if df.empty:
        return "no finished cells"
    texts = {s: reference_text(g, name) for s, g in df.groupby("scene", sort=True)}
    if len(set(texts.values())) == 1:
        return next(iter(texts.values())) + " in every scene"
    return "per scene, " + "; ".join(f"{name(s)}: {t}" for s, t in texts.items())


def next_pow2(x: float) -> int:
    return int(2 ** math.ceil(math.log2(max(x, 1.0))))


def ref_share(r: Any) -> tuple[float, str]:
    """(share, share_on) of one cell's row (:func:`ref_noise_frame`): the reference's error
    over the method's, NaN (share_on "") where the row lacks a finite pair of the two."""
    ref, err = num(r.get("ref_rmse")), num(r.get("rmse"))
    ref_rel, rel = num(r.get("ref_relmse_surface")), num(r.get("relmse_surface"))
    if math.isfinite(ref_rel) and math.isfinite(rel) and rel > 0:
        return ref_rel / rel, "relmse_surface"
    if math.isfinite(ref) and math.isfinite(err) and err > 0:
        return ref * ref / (err * err), "rmse"
    return math.nan, ""


def ref_unchecked(df: pd.DataFrame) -> int:
    """How many cells of ``df`` :func:`ref_noise_frame` cannot check (no finite pair of the
    reference's and the method's error: a method's NaN output)."""
    return sum(not math.isfinite(ref_share(r)[0]) for _, r in df.iterrows())


def ref_noise_frame(df: pd.DataFrame) -> pd.DataFrame:
    """Cells whose reference error exceeds :data:`REF_SHARE` of the method's, with the
    ``--ref-spp`` that would bring it under: ref_spp · share / 0.1, rounded up to a power of two
    (the reference variance scales as 1 / ref_spp).

    The share is on the ranked metric over surface pixels, ref_relmse_surface /
    relmse_surface (``share_on`` "relmse_surface"): lights seen directly hold most of a
    method's squared error and hide a noisy reference from ref_rmse² / rmse². Cells without
    those two figures (older cells, sequences) keep ref_rmse² / rmse² (``share_on`` "rmse")."""
    cols = ["scene", "spp", "method", "ref_spp", "ref_rmse", "rmse", "ref_mse_share",
            "share_on", "needed_ref_spp", "res"]
    if df.empty or not {"ref_rmse", "ref_relmse_surface"} & set(df.columns):
        return pd.DataFrame(columns=cols)
    rows = []
    for _, r in df.iterrows():
        ref, err, n = num(r.get("ref_rmse")), num(r.get("rmse")), num(r.get("ref_spp"))
        share, on = ref_share(r)
        if share > REF_SHARE:
            need = next_pow2(n * share / REF_SHARE) if math.isfinite(n) and n > 0 else np.nan
            rows.append({"scene": r["scene"], "spp": int(r["spp"]), "method": r["method"],
                         "ref_spp": n, "ref_rmse": ref, "rmse": err, "ref_mse_share": share,
                         "share_on": on, "needed_ref_spp": need, "res": r.get("res")})
    out = pd.DataFrame(rows, columns=cols)
    return out.sort_values(["scene", "spp", "method"]).reset_index(drop=True)


def seconds_text(s: float) -> str:
    """``45 s``, ``12 min``, ``3.5 h``: a duration for a sentence."""
    if s < 120:
        return f"{s:.2g} s" if s < 10 else f"{s:.0f} s"
    return f"{s / 60:.0f} min" if s < 7200 else f"{s / 3600:.1f} h"


def ref_cost_text(cells: Iterable[dict], scene: str, res: Any, ref_spp: float,
                  need: float) -> str:
    """What a ``need``-spp reference of ``scene`` at ``res`` would take to render, from the
    ``ref_render_s`` the cells record for their ``ref_spp`` reference, scaled linearly with spp
    (a reference is ``ref_spp`` independent samples per pixel: README.md, "How renders work"),
    and the machine and Mitsuba variant those cells name; '' when no cell records the time.
    Cached references keep the time of their first render."""
    from ..errors import DbenchInputError
    from ..resolution import parse_res

    def key(v: Any):
        try:
            return parse_res(v).key
        except (DbenchInputError, TypeError, ValueError):  # unreadable: not this reference's
            return None

    times: dict[Any, float] = {}
    machines: set[str] = set()
    for c in cells:
        if (not isinstance(c, dict) or c.get("status", "ok") != "ok" or c.get("scene") != scene
                or num(c.get("ref_spp")) != ref_spp or key(c.get("res")) != res):
            continue
        t = num(c.get("ref_render_s"))
        if math.isfinite(t) and t > 0:
            times[repr(c.get("ref_seed"))] = t  # one time per distinct reference
            if isinstance(c.get("machine"), str) and c["machine"]:
                v = c.get("render_variant")  # what rendered it: CUDA and LLVM differ in time
                machines.add(c["machine"] + (f", {v}" if isinstance(v, str) and v else ""))
    if not times or not (math.isfinite(ref_spp) and ref_spp > 0 and math.isfinite(need)):
        return ""
    t = float(np.median(list(times.values())))
    where = ("on " + "; ".join(sorted(machines)) if machines
             else "on a machine the cells do not record")
    return (f"about {seconds_text(t * need / ref_spp)} to render "
            f"({need / ref_spp:g}× the {int(ref_spp)}-spp reference's {seconds_text(t)} "
            f"measured {where}, scaled linearly with spp)")


def ref_warnings_md(df: pd.DataFrame, cells: Iterable[dict] | None = None,
                    name: Namer = markdown_text) -> list[str]:
    """One line per (scene, spp) with a too-noisy reference, listing the methods; with the raw
    ``cells``, what the suggested reference would cost (:func:`ref_cost_text`). ``name``
    writes the scenes' and methods' names (the terminal's lines: as they are)."""
    bad = ref_noise_frame(df)
    cells, lines = list(cells or []), []
    for (scene, spp), g in bad.groupby(["scene", "spp"], sort=True):
        need = g["needed_ref_spp"].max()
        refs = sorted({int(v) for v in g["ref_spp"] if _finite(v)})
        # a folder's reference is one of its files, which --ref-spp cannot change
        files = "files" in set(df[df["scene"] == scene].get("render_variant", ()))
        fix = ((f"a reference of at least {int(need)} spp in the folder" if files else
                f"`--ref-spp {int(need)}`") + " would bring it under 10 %" if _finite(need)
               else "a reference with more samples would fix it")
        if _finite(need) and cells and not files:
            worst = g.loc[g["needed_ref_spp"].idxmax()]
            cost = ref_cost_text(cells, scene, worst["res"], num(worst["ref_spp"]), need)
            fix += f", {cost}" if cost else ""
        on = " and ".join(
            {"relmse_surface": "relMSE over surface pixels", "rmse": "MSE"}[o]
            for o in sorted(set(g["share_on"]), reverse=True))
        lines.append(
            f"- ⚠ {name(scene)}, {spp} spp: the reference's error is above 10 % of the "
            f"method's (reference / method on {on}, up to {g['ref_mse_share'].max():.2g}) for "
            f"{', '.join(map(name, g['method']))}"
            + (f"; reference {', '.join(map(str, refs))} spp" if refs else "") + f"; {fix}.")
    return lines


def headline_spp(spps: Iterable[Any], preferred: int = 64) -> int | None:
    """``preferred`` if present, else the spp closest to it (in log2; the lower on a tie)."""
    vals = sorted({int(s) for s in spps if _finite(s) and s > 0})
    if not vals:
        return None
    if preferred in vals:
        return preferred
    return min(vals, key=lambda s: (abs(math.log2(s) - math.log2(preferred)), s))


__all__ = ["METRICS", "HEADLINE", "HIGHER_IS_BETTER", "DEFINITIONS", "TIME", "headline_columns",
           "definitions", "REF_RMSE_DEFINITION", "CI_DEFINITION", "REF_SHARE", "NOISY", "num",
           "half_width", "fmt_value", "overlaps", "seed_values", "paired_interval", "tie",
           "TIE_WORDS", "marked", "rank_groups", "ranking_line", "ranking_metric", "ci_kind_text",
           "reference_text", "reference_summary", "ref_noise_frame", "ref_warnings_md",
           "ref_cost_text", "seconds_text", "headline_spp", "expected_grid", "grid_status",
           "grid_status_text", "missing_md", "next_pow2", "finite", "ref_share", "ref_unchecked"]
