"""Tables from sweep cells (pandas → CSV / Markdown).

* :func:`cells_frame`: one row per finished cell, every metric with its 95 % half-width
  (``<metric>_ci``), the interval kind, the reference actually used and the times;
* convergence: for each metric, scene × spp with a row per method label (ProDen's layout); the
  CSV keeps numbers with separate ``<spp> spp_ci`` columns, Markdown shows ``mean ± ci``;
* equal time: for rmse, relmse and rmse_surface, the spp at which plain rendering reaches the
  method's error (log-log fit of the noisy input's metric against spp on the same scene) and the
  time saved (positive) or lost (negative) against rendering that many samples instead.

Plots live in :mod:`dbench.report.plots`; verdicts (ties, rankings) in
:mod:`dbench.report.verdicts`.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Collection, Sequence

import numpy as np
import pandas as pd

from ..errors import DbenchInputError
from ..metrics import records
from ..resolution import parse_res
from .cells import device_label
from .formats import markdown_table, markdown_text, write_csv
from .verdicts import HEADLINE, METRICS, fmt_value, num, seed_values

ID_COLUMNS = ["scene", "method", "base_method", "spp", "res", "n_seeds", "ci_kind", "ref_spp",
              "ref_rmse", "ref_relmse_surface", "render_variant", "device", "backend"]
TIME_COLUMNS = ["time_s", "time_s_iqr", "render_s", "gradient_s", "total_s"]
#: The sequence-only metrics (temporal and video records).
TEMPORAL = records.sequence_metrics()
#: Every metric column of a cell: the verdicts' metrics and the sequence-only ones they lack.
COLUMNS = METRICS + tuple(m for m in TEMPORAL if m not in METRICS)
EQUAL_TIME_METRICS = ("rmse", "relmse", "rmse_surface")
#: The log-log slope below which the noisy input's error falls as spp grows: a flat error (the
#: same at every spp; a fit's rounding leaves a slope of −5e-16) reaches no method's error at
#: any spp, and dividing by it overflows (Monte Carlo error falls with slope −0.5).
FALLING = -1e-6


def _label(v) -> str | None:
    return v if isinstance(v, str) and v else None


def _res_key(value: Any) -> int | str | float:
    """A cell's ``res`` in its key form (256 or "160x90"), NaN when it is not a size."""
    try:
        return parse_res(value).key
    except DbenchInputError:
        return float("nan")


def _row(c: dict) -> dict | None:
    scene, method = _label(c.get("scene")), _label(c.get("method"))
    spp = num(c.get("spp"))
    if scene is None or method is None or not np.isfinite(spp):
        return None
    row = {"scene": scene, "method": method,
           "base_method": _label(c.get("base_method")) or method.split("[")[0],
           "spp": int(spp), "res": _res_key(c.get("res")), "n_seeds": num(c.get("n_seeds")),
           "ci_kind": _label(c.get("ci_kind")) or "", "ref_spp": num(c.get("ref_spp")),
           "ref_rmse": num(c.get("ref_rmse")),
           "ref_relmse_surface": num(c.get("ref_relmse_surface")),
           # what rendered the inputs ("files": a folder's renders, its reference a file)
           "render_variant": _label(c.get("render_variant")) or "",
           # where the method was timed (docs/gpu.md §3): GPU and CPU times are never unnamed
           "device": device_label(c), "backend": _label(c.get("backend")) or ""}
    for m in COLUMNS:
        row[m] = num(c.get(m))
        row[m + "_ci"] = num(c.get(m + "_ci"))
    stats = num(c.get("stats_s"))
    render = num(c.get("render_s"))
    row["time_s"] = num(c.get("time_s"))
    row["time_s_iqr"] = num(c.get("time_s_iqr"))
    row["render_plain_s"] = render
    row["stats_s"] = stats if np.isfinite(stats) else 0.0
    row["render_measured_s"] = render + row["stats_s"]
    gradient = num(c.get("gradient_s"))
    # per frame: rendering A-SVGF's re-shaded samples for a method that uses them
    row["gradient_s"] = gradient if np.isfinite(gradient) else 0.0
    row["n_nonfinite"] = num(c.get("n_nonfinite"))
    # calls on one input that gave different outputs (dbench/run/harness.py): NaN where none did
    nd = c.get("nondeterministic") if isinstance(c.get("nondeterministic"), dict) else {}
    row["nondeterministic_abs"] = num(nd.get("max_abs_diff"))
    row["nondeterministic_rel"] = num(nd.get("max_rel_diff"))
    # other groups that could run while it was timed (dbench sweep --workers N; NaN: older)
    row["timed_beside"] = num(c.get("timed_beside"))
    row["per_seed"] = seed_values(c.get("per_seed"))
    return row


def _per_spp_cost(values: pd.Series, spp: pd.Series) -> float:
    """Median seconds per spp over a scene's ladder, its lowest spp left out when there are
    others (the first render of a scene in a process carries one-time JIT compilation)."""
    keep = spp > spp.min() if spp.nunique() > 1 else spp > 0
    per = (values[keep] / spp[keep]).replace([np.inf, -np.inf], np.nan).dropna()
    return float(per.median()) if len(per) else float("nan")


def _model_render_time(df: pd.DataFrame) -> pd.DataFrame:
    """``render_s`` = the scene's rendering cost per spp × spp, plus its statistics cost per
    spp × spp for cells that collect statistics (costs: :func:`_per_spp_cost` over the scene's
    cells); ``total_s`` = ``render_s`` + ``time_s`` + ``gradient_s`` (the per-frame cost of
    the re-shaded gradient samples, for the methods that use them). A single render's wall time carries
    compilation and whatever else ran on the machine; the per-spp model does not, and makes the
    error-against-time curves comparable along the ladder. ``render_measured_s`` keeps the
    measured seconds."""
    df = df.copy()
    df["render_s"] = df["render_measured_s"]
    for scene, g in df.groupby("scene"):
        per_spp = g.drop_duplicates("spp")
        render_cost = _per_spp_cost(per_spp["render_plain_s"], per_spp["spp"])
        with_stats = g[g["stats_s"] > 0].drop_duplicates("spp")
        stats_cost = (_per_spp_cost(with_stats["stats_s"], with_stats["spp"])
                      if len(with_stats) else 0.0)
        if not np.isfinite(render_cost):
            continue
        idx = g.index
        df.loc[idx, "render_s"] = render_cost * g["spp"] + np.where(
            g["stats_s"] > 0, stats_cost * g["spp"], 0.0)
    df["total_s"] = df["render_s"] + df["time_s"] + df["gradient_s"]
    return df


def cells_frame(cells: list[dict]) -> pd.DataFrame:
    """One row per ``ok`` cell. Missing or malformed values are NaN; cells without a scene,
    method label or spp are left out; ``per_seed`` holds each cell's {seed: {metric: value}}
    (:func:`~.verdicts.seed_values`, for paired verdicts). ``render_s`` is the modelled
    rendering time of the cell's spp, statistics collection included where the method needs it
    (:func:`_model_render_time`;
    ``render_measured_s`` the measured one), ``gradient_s`` the per-frame cost of the re-shaded
    gradient samples where the method uses them, and ``total_s`` = ``render_s`` + ``time_s`` +
    ``gradient_s``. The temporal metrics are kept only when some cell has them (sequence
    scenes). ``attrs["recorded"]``: the metric and time columns some finished cell holds a
    number for, NaN included (a NaN is a value the cell computed, a missing key one it never
    did: :func:`unshown_md` tells them apart)."""
    ok = [c for c in cells if isinstance(c, dict) and c.get("status") == "ok"]
    cols = ID_COLUMNS + [k for m in COLUMNS for k in (m, m + "_ci")] + TIME_COLUMNS + [
        "n_nonfinite", "nondeterministic_abs", "nondeterministic_rel", "timed_beside"]
    rows = [r for c in ok if (r := _row(c)) is not None]
    df = pd.DataFrame(rows, columns=cols + ["render_plain_s", "stats_s", "render_measured_s",
                                            "per_seed"])
    for c in df.columns:
        if c not in ("scene", "method", "base_method", "ci_kind", "res", "per_seed",
                     "render_variant", "device", "backend"):
            df[c] = df[c].astype(float) if c != "spp" else df[c].astype(int)
    df = _model_render_time(df).drop(columns=["render_plain_s", "stats_s"])
    recorded = frozenset(m for m in (*COLUMNS, *TIME_COLUMNS) for c in ok
                         if isinstance(c.get(m), (int, float)) and not isinstance(c.get(m), bool))
    drop = [k for m in TEMPORAL if m not in recorded for k in (m, m + "_ci")]
    df = df.drop(columns=drop)
    df = df.sort_values(["scene", "spp", "method"], kind="stable").reset_index(drop=True)
    df.attrs["recorded"] = recorded
    return df


def unshown_md(df: pd.DataFrame, columns: list[str], lead: str = "Not recorded in these cells"
               ) -> list[str]:
    """Why ``columns`` (metrics no cell of ``df`` holds a finite value of) are not shown, as
    Markdown lines: those no finished cell records (older cells, another kind of scene) after
    ``lead``, those every cell that records them holds as NaN or Inf (``attrs["recorded"]``,
    :func:`cells_frame`) named as such; [] when ``columns`` is empty."""
    recorded = df.attrs.get("recorded", frozenset())
    absent = [c for c in columns if c not in recorded]
    nan = [c for c in columns if c in recorded]
    return ([f"{lead}: {', '.join(absent)}.", ""] if absent else []) + (
        [f"Not finite in any cell that records it (NaN or Inf): {', '.join(nan)}.", ""]
        if nan else [])


def convergence_table(df: pd.DataFrame, metric: str, ci: bool = True) -> pd.DataFrame:
    """Rows (scene, method), columns ``<spp> spp`` and (``ci``) ``<spp> spp_ci``."""
    cols = [metric] + ([metric + "_ci"] if ci and metric + "_ci" in df.columns else [])
    if df.empty:
        return pd.DataFrame(columns=["scene", "method"])
    t = df.pivot_table(index=["scene", "method"], columns="spp", values=cols,
                       aggfunc="first", dropna=False)
    out = pd.DataFrame(index=t.index)
    for spp in sorted(df.spp.unique()):
        out[f"{spp} spp"] = t[(metric, spp)] if (metric, spp) in t.columns else np.nan
        if len(cols) > 1:
            out[f"{spp} spp_ci"] = t[(cols[1], spp)] if (cols[1], spp) in t.columns else np.nan
    return out.reset_index()


#: What a convergence entry says where a cell exists but has no value of the metric, and where
#: the method does not apply to the scene (its cell is skipped): "—" is kept for "no cell", so
#: a finished or skipped cell never reads as one that was not run.
NONFINITE, NO_VALUE, NOT_APPLICABLE = "no value (non-finite output)", "no value", "n/a"
#: The line under a convergence table that holds :data:`NOT_APPLICABLE`.
NOT_APPLICABLE_NOTE = ("n/a: the method does not apply to the scene (its cell is skipped, "
                       "not run); —: no cell.")


def skipped_keys(cells: Sequence[dict]) -> set[tuple[str, str, str]]:
    """(scene, method label, ``<spp> spp``) of every skipped cell: a method that does not apply
    to the scene (a temporal method on a still image)."""
    return {(str(c.get("scene")), str(c.get("method")), f"{c.get('spp')} spp")
            for c in cells if isinstance(c, dict) and c.get("status") == "skipped"}


def convergence_table_md(df: pd.DataFrame, metric: str,
                         skipped: Collection[tuple[str, str, str]] = ()) -> pd.DataFrame:
    """Like :func:`convergence_table` with ``mean ± ci`` strings: ``—`` where no cell,
    :data:`NOT_APPLICABLE` where the cell is one of ``skipped`` (:func:`skipped_keys`),
    :data:`NONFINITE` where the cell's outputs held non-finite values (its metrics are NaN,
    README.md "Metrics"), :data:`NO_VALUE` where the cell has no value of ``metric``."""
    t = convergence_table(df, metric)
    spps = [c for c in t.columns if c.endswith(" spp")]
    out = t[["scene", "method"]].copy()
    nonfinite = df.get("n_nonfinite", pd.Series(np.nan, index=df.index))
    held = {(r.scene, r.method, f"{r.spp} spp"): n for r, n in zip(df.itertuples(), nonfinite)}
    for c in spps:
        cis = t[c + "_ci"] if c + "_ci" in t.columns else [np.nan] * len(t)
        out[c] = [fmt_value(m, h) if np.isfinite(m) else
                  (NONFINITE if held[(s, k, c)] > 0 else NO_VALUE) if (s, k, c) in held else
                  NOT_APPLICABLE if (s, k, c) in skipped else "—"
                  for s, k, m, h in zip(t["scene"], t["method"], t[c], cis)]
    return out


def convergence_md(df: pd.DataFrame, metric: str, cells: Sequence[dict]) -> list[str]:
    """The Markdown convergence table of ``metric`` (:func:`convergence_table_md`, the cells
    skipped in ``cells`` marked :data:`NOT_APPLICABLE`) and, where it holds one, the line
    that says what it means."""
    t = convergence_table_md(df, metric, skipped_keys(cells))
    marked = (t.drop(columns=["scene", "method"]) == NOT_APPLICABLE).to_numpy().any()
    return [markdown_table(t), ""] + ([NOT_APPLICABLE_NOTE, ""] if marked else [])


def noisy_fit(df: pd.DataFrame, scene: str, metric: str = "rmse") -> tuple[float, float] | None:
    """Least-squares fit log metric = a + b log spp of the noisy input on ``scene``."""
    if metric not in df.columns:
        return None
    d = df[(df.scene == scene) & (df.method == "noisy")].dropna(subset=[metric])
    d = d[d[metric] > 0]
    if len(d) < 2 or d.spp.nunique() < 2:
        return None
    b, a = np.polyfit(np.log(d.spp.astype(float)), np.log(d[metric].astype(float)), 1)
    return float(a), float(b)


def render_cost_per_spp(df: pd.DataFrame, scene: str) -> float:
    """Seconds per spp of plain sample rendering on ``scene`` (the noisy input's modelled
    render time per spp)."""
    d = df[(df.scene == scene) & (df.method == "noisy")]
    per = (d.render_s / d.spp).replace([np.inf, -np.inf], np.nan).dropna()
    return float(per.median()) if len(per) else float("nan")


def equal_time_table(df: pd.DataFrame, metrics: tuple[str, ...] = EQUAL_TIME_METRICS
                     ) -> pd.DataFrame:
    """Per (scene, method, spp) and metric: ``equal_<m>_spp`` (plain rendering's spp at the
    method's error), ``equal_<m>_render_s`` and ``<m>_time_saved_s``."""
    metrics = tuple(m for m in metrics if m in df.columns)
    rows = []
    for scene in sorted(df.scene.unique()):
        cost = render_cost_per_spp(df, scene)
        fits = {m: noisy_fit(df, scene, m) for m in metrics}
        d = df[(df.scene == scene) & (df.method != "noisy")].sort_values(["method", "spp"])
        for _, r in d.iterrows():
            row = {"scene": scene, "method": r.method, "spp": r.spp, "render_s": r.render_s,
                   "denoise_s": r.time_s, "total_s": r.total_s}
            for m in metrics:
                fit, v = fits[m], r[m]
                eq = np.nan
                if fit is not None and np.isfinite(v) and v > 0 and fit[1] < FALLING:
                    with np.errstate(over="ignore"):  # beyond any spp: no figure, not inf
                        eq = float(np.exp((np.log(v) - fit[0]) / fit[1]))
                    eq = eq if np.isfinite(eq) else np.nan
                row.update({m: v, f"equal_{m}_spp": eq, f"equal_{m}_render_s": eq * cost,
                            f"{m}_time_saved_s": eq * cost - r.total_s})
            rows.append(row)
    return pd.DataFrame(rows)


def equal_time_md(df: pd.DataFrame, spp: int) -> pd.DataFrame:
    """The equal-time table at one spp, compact: the equal spp and time saved per metric."""
    eq = equal_time_table(df)
    if eq.empty:
        return eq
    eq = eq[eq.spp == spp]
    cols = ["scene", "method", "total_s"] + [c for m in EQUAL_TIME_METRICS
                                             for c in (f"equal_{m}_spp", f"{m}_time_saved_s")
                                             if c in eq.columns and eq[c].notna().any()]
    out = eq[cols].reset_index(drop=True)
    return out.astype(object).where(out.notna(), "—")  # as convergence_table_md marks a gap


def equal_time_gaps(df: pd.DataFrame, lead: str = "No equal-time figure (—) for") -> list[str]:
    """Why the equal-time table has no figure for a scene and metric (a Markdown paragraph and
    a blank line, or nothing): the noisy input's error there has fewer than two spp to fit, or
    does not fall as spp grows (fit slope ≥ 0, e.g. a firefly at the higher spp), so no spp of
    plain rendering reaches a method's error by that fit. ``lead`` opens the paragraph (no
    table at all: "No equal-time table: no fit for")."""
    gaps = []
    for scene in sorted(df.scene.unique()):
        for m in (m for m in EQUAL_TIME_METRICS if m in df.columns):
            fit = noisy_fit(df, scene, m)
            if fit is None:
                gaps.append(f"{markdown_text(scene)} on {m} (fewer than two spp of the noisy "
                            "input)")
            elif fit[1] >= FALLING:
                gaps.append(f"{markdown_text(scene)} on {m} (the noisy input's {m} does not "
                            f"fall as spp grows: log-log slope {fit[1]:+.2f})")
    return [f"{lead} {'; '.join(gaps)}: no spp of plain rendering "
            "reaches a method's error by that fit.", ""] if gaps else []


def headline_table(df: pd.DataFrame, spp: int) -> pd.DataFrame:
    d = df[df.spp == spp]
    if d.empty:
        return d
    cols = [c for c in ("scene", "method", *HEADLINE) if c in d.columns]
    return d[cols].sort_values(["scene", "method"]).reset_index(drop=True)


def write_tables(df: pd.DataFrame, out: Path) -> dict[str, Path]:
    """CSV files of every table under ``out``; returns their paths. A convergence CSV is
    written for each metric some cell records (numbers, with ``_ci`` columns; none without a
    finished cell, whose tables would be headers alone, never linked); one an earlier
    report wrote for a metric these cells do not record is removed, never left with the old
    cells' numbers."""
    from .verdicts import ref_noise_frame

    paths = {}
    every_cell = records.judged()  # written even when no cell has a value
    for metric in COLUMNS:
        p = out / f"convergence_{metric}.csv"
        # without a finished cell a table would be its header alone: none is written
        if len(df) and metric in df.columns and (df[metric].notna().any()
                                                 or metric in every_cell):
            write_csv(p, convergence_table(df, metric))
            paths[f"convergence_{metric}"] = p
        else:
            p.unlink(missing_ok=True)
    paths["equal_time"] = out / "equal_time.csv"
    write_csv(paths["equal_time"], equal_time_table(df))
    paths["reference_noise"] = out / "reference_noise.csv"
    write_csv(paths["reference_noise"], ref_noise_frame(df))
    paths["cells"] = out / "cells.csv"
    write_csv(paths["cells"], df.drop(columns=["per_seed"], errors="ignore")
              .sort_values(["scene", "spp", "method"]))
    return paths


def convergence_plot(df: pd.DataFrame, path: Path) -> bool:  # kept for callers of tables
    from .plots import convergence_plot as plot

    return plot(df, path)


__all__ = ["NONFINITE", "NO_VALUE", "NOT_APPLICABLE", "NOT_APPLICABLE_NOTE", "cells_frame",
           "convergence_table", "convergence_table_md", "skipped_keys", "convergence_md",
           "noisy_fit",
           "render_cost_per_spp", "equal_time_table", "equal_time_md", "equal_time_gaps",
           "headline_table", "write_tables", "convergence_plot", "markdown_table"]
