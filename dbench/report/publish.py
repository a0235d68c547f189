"""``dbench report``: rebuild ``results/README.md`` from result files only.

Inputs: a sweep folder (cell JSON files and ``sweep.json`` with the settings and the machine it
ran on), ``stress.md``, and optional extra Markdown files (per-issue results such as
``statistical.md``). Nothing is timed or rendered here and no clock is read, so the same files
give the same README byte for byte (figures are written with fixed PNG metadata).

Verdicts follow docs/judging.md: every entry is ``mean ± 95 % half-width``, methods whose
paired difference to the best over common seeds includes 0 (without common seeds: whose
intervals overlap the best's) are tied, rankings use ``rank_by`` (relMSE by default), the
reference spp is read from the cells (never the config) and a reference whose own error is
above 10 % of a method's MSE is flagged with the ``--ref-spp`` that would fix it.
"""
from __future__ import annotations

from pathlib import Path

from .. import io
from ..resolution import size_text
from . import headline, plots, tables, verdicts
# load_sweep and wall_text are imported for this module's callers too, as before
from .cells import (INPUT_WARNINGS_INTRO, input_warnings, load_sweep,  # noqa: F401
                    mixed_md, problems_md, run_notes, run_notes_md, side_by_side_text,
                    wall_text)
from .formats import counted, markdown_code, markdown_table, markdown_text
from .html import sweep_page
from .run_report import machine_md, metric_definitions_md
from .table31 import table31_file, table31_md

#: Metrics shown as Markdown convergence tables in the README (others: CSV links).
README_CONVERGENCE = ("rmse", "relmse", "rmse_surface")
#: Headline columns of published sequence and transient sweeps (steady: verdicts.HEADLINE).
SEQUENCE_HEADLINE = verdicts.headline_columns("sequence")
TRANSIENT_HEADLINE = verdicts.headline_columns("transient")


def _config(info: dict) -> dict:
    c = info.get("config", {})
    return c if isinstance(c, dict) else {}


def _labels(config: dict) -> list:
    return list(config.get("labels") or config.get("methods") or [])


def _pick_rank(df, rank_by: str) -> str:
    """``rank_by`` when some cell records it, else rmse (old or partial sweeps)."""
    if rank_by in df.columns and df[rank_by].notna().any():
        return rank_by
    return "rmse"


def settings_line(config: dict, df, status: dict, rel_name: str, extras=(),
                  name: verdicts.Namer = markdown_text) -> str:
    """The sweep's settings in one paragraph of the README; ``name`` writes the scenes' and
    methods' names (the viewer's line, which escapes HTML: as they are)."""
    scenes = config.get("scenes") or sorted(df.scene.unique())
    seeds = config.get("seeds")
    seeds = seeds if isinstance(seeds, int) else 1
    ref = config.get("ref_spp")
    return (f"Sweep {markdown_code(rel_name)}: {counted(len(scenes), 'scene')} "
            f"({', '.join(map(name, scenes))}) × {counted(len(_labels(config)), 'method label')}"
            " × spp "
            f"{', '.join(map(str, config.get('spp', [])))}, {size_text(config.get('res'))} px, "
            f"{counted(seeds, 'seed')} (first seed "
            f"{config.get('seed')}); {verdicts.reference_summary(df, name)} (read from the cells; "
            f"requested: {f'--ref-spp {ref}' if ref else 'the default'}); "
            + "".join(f"{e}; " for e in extras)
            + f"{verdicts.grid_status_text(status, name)}.")


def reference_md(df, rel_csv: str | None = None, cells: list | None = None) -> list[str]:
    """The reference-noise warnings (with ``cells``, their cost), or why there are none."""
    if "ref_rmse" not in df.columns or not df["ref_rmse"].notna().any():
        return ["The cells do not record `ref_rmse` (older format): the reference's own noise "
                "is not checked here.", ""]
    warn, unchecked = verdicts.ref_warnings_md(df, cells), verdicts.ref_unchecked(df)
    if unchecked == len(df):  # every method's error NaN: nothing to hold the reference's to
        return ["No cell records a finite error for its method (NaN or Inf): the reference's "
                "own noise cannot be checked here.", ""]
    if not warn:
        return ["No cell's reference error exceeds 10 % of the method's"
                + (f" ({counted(unchecked, 'cell')} without a finite error not checked)."
                   if unchecked else "."), ""]
    return (["Reference too noisy for these cells (its relMSE over surface pixels above "
             "0.1 · relmse_surface, or ref_rmse² > 0.1 · rmse² where a cell lacks it; the "
             "reference's variance scales as 1 / ref_spp, its cost as ref_spp):", ""] + warn
            + [""] + ([f"Every flagged cell: [{rel_csv}]({rel_csv}).", ""] if rel_csv else []))


def _listed_md(title: str, intro: str, said: list[str]) -> list[str]:
    """A section ``title``: ``intro`` (with ``{run}``, the command as code), then ``said`` as
    a list; nothing where ``said`` is empty."""
    return [title, "", intro.format(run="`dbench run`"), ""] + [
        f"- {markdown_text(line)}" for line in said] + [""] if said else []


def input_warnings_md(cells: list[dict], title: str) -> list[str]:
    """A section ``title`` listing what the cells' inputs said of themselves
    (:func:`dbench.report.cells.input_warnings`), or nothing where they said nothing."""
    return _listed_md(title, INPUT_WARNINGS_INTRO, input_warnings(cells))


def nondeterministic_md(cells: list[dict], title: str) -> list[str]:
    """A section ``title`` listing the cells whose method's calls on one input differed
    (:func:`dbench.report.headline.nondeterministic_lines`), or nothing where none did."""
    return _listed_md(title, headline.NONDETERMINISTIC_INTRO,
                      headline.nondeterministic_lines(cells))


def build_readme(results: Path, sweep_dir: Path, headline_spp: int = 64,
                 rank_by: str = "relmse") -> str:
    results, sweep_dir = Path(results), Path(sweep_dir)
    info, cells, problems = load_sweep(sweep_dir)
    config = _config(info)
    df = tables.cells_frame(cells)
    rank = _pick_rank(df, rank_by)
    status = verdicts.grid_status(config, cells)
    rel = lambda p: Path(p).relative_to(results).as_posix()  # noqa: E731
    paths = tables.write_tables(df, sweep_dir / "tables")
    converged = plots.convergence_plot(df, sweep_dir / "convergence.png")
    figures = {m: sweep_dir / f"error_time_{m}.png" for m in ("rmse_surface", "relmse")}
    drawn = {m: plots.error_time_plot(df, m, p) for m, p in figures.items()}

    parts = ["# dbench results", "",
             "Generated by `dbench report` from the files in this folder; do not edit by hand. "
             "The same numbers, sortable, with the figures: [index.html](index.html) (open it "
             "in a browser; no network needed).", ""]
    sequence = any(c.get("frames") for c in cells)
    reps, seeds = config.get("repeats"), config.get("seeds")
    timing = f"denoise time = median over {headline.timing_words(reps, seeds)} (rendering excluded)"
    # --repeats times steady and transient cells only; a sequence's time is said after this line
    single = any(not c.get("frames") for c in cells if c.get("status") == "ok") or not sequence
    timing = ("steady and transient scenes: " + timing if sequence else timing) if single else ""
    parts += [settings_line(config, df, status, rel(sweep_dir),
                            [t for t in [timing, wall_text(info, cells)] if t]) + (
        " Sequence scenes: each frame denoised once, in order; metrics are means and time the "
        "median per frame after the 8-frame warm-up (all of a sequence of 8 or fewer)."
        if sequence else ""), ""] + run_notes_md(info)
    spp = verdicts.headline_spp(df.spp.unique(), headline_spp) if len(df) else None
    if spp is None:  # nothing ranks, and no cell says what its metrics or reference were
        parts += ["## Headline", "", "No finished cell: nothing to rank (every cell failed, "
                  "does not apply or is missing; see below).", ""]
    else:
        parts += [f"## Headline: every method × every scene at {spp} spp", ""]
        if rank != rank_by:
            why = ("is not finite in any cell" if rank_by in df.attrs.get("recorded", ())
                   else "is not recorded in these cells")
            parts += [f"(`{rank_by}` {why}: ranked by `{rank}`.)", ""]
        parts += headline.headline_md(df, spp, rank, scene_columns=scene_columns(cells))
        parts += ["### Reference noise", ""] + reference_md(df, rel(paths["reference_noise"]),
                                                            cells)

    parts += input_warnings_md(cells, "## Input warnings")
    parts += nondeterministic_md(cells, "## Not reproducible")
    lines = problems_md(cells, problems, status["missing"])
    if lines:
        parts += ["## Skipped and failed cells", ""] + lines + [""]
    if status["mixed"]:  # one row or table holding cells of other settings or code
        parts += ["## Mixed settings", "", "These cells were computed with different settings "
                  "or code, yet stand side by side in the tables below (a `--rerun` over part "
                  "of the grid recomputes only that part); `dbench sweep ... --rerun` over the "
                  "whole grid makes them alike:", ""] + mixed_md(status["mixed"]) + [""]

    parts += ["## Convergence", "", f"![convergence]({rel(sweep_dir / 'convergence.png')})"
              if converged else "No convergence figure: no finished cell records a finite rmse "
              "(see the cells above).", "",
              "Entries are mean ± 95 % half-width (— where no cell; \"no value (non-finite "
              "output)\" where the cell's outputs held NaN or Inf).", ""]
    for metric in README_CONVERGENCE:
        if metric in df.columns and df[metric].notna().any():
            parts += [f"### {metric.upper()} (rows scene/method, columns spp)", ""
                      ] + tables.convergence_md(df, metric, cells)
    others = [m for m in verdicts.METRICS if f"convergence_{m}" in paths
              and m not in README_CONVERGENCE]
    parts += ["Other metrics (CSV, numbers with `_ci` columns): " + ", ".join(
        f"[{m}]({rel(paths['convergence_' + m])})" for m in others) + ".", ""] if others else []
    if len(df):  # without cells, nothing is recorded, and no format is older
        parts += [("`rmse_unbiased` removes the reference's own noise, sqrt(max(0, MSE − mean "
                   "reference variance)): " + (
                       f"[{rel(paths['convergence_rmse_unbiased'])}]"
                       f"({rel(paths['convergence_rmse_unbiased'])})."
                       if "convergence_rmse_unbiased" in paths else
                       "not recorded in these cells (older format).")), ""]

    parts += ["## Error against time", "",
              "One panel per scene: x = render + denoise time (render includes statistics "
              "collection), y = error, one line per method label through its spp points; the "
              "noisy input dashed; the grey step line is the lower envelope over every point, "
              f"the {plots.ENVELOPE_LABEL} (labelled with the method that owns each segment). "
              "Render time is the scene's measured cost per spp × spp (median seconds per spp "
              "over the ladder, the lowest spp left out because the first render of a scene "
              "carries one-time JIT compilation), plus the statistics' cost per spp for methods "
              "that need them; each cell's measured seconds are in `tables/cells.csv` "
              "(`render_measured_s`).",
              ""]
    for m, p in figures.items():
        parts += ([f"![error against time, {m}]({rel(p)})", ""] if drawn[m] else
                  [f"({m} against time: no cell records both.)", ""])
    parts += ["Equal-time view: `equal_<m>_spp` is the spp at which plain rendering reaches the "
              "method's error on metric m (log-log fit of the noisy input's m against spp on "
              "the same scene); `<m>_time_saved_s` = time to render that many samples − "
              "(render + denoise time of the method). Positive: denoising beats rendering more "
              "samples.", ""]
    eq = tables.equal_time_md(df, spp) if spp is not None else None
    if eq is not None and any(c.startswith("equal_") for c in eq.columns):
        parts += [f"At {spp} spp:", "", markdown_table(eq, ".3g"), "", *tables.equal_time_gaps(
            df), f"All spp: [{rel(paths['equal_time'])}]({rel(paths['equal_time'])})", ""]
    elif eq is not None and len(eq):  # a table of times alone would say nothing
        parts += tables.equal_time_gaps(df, "No equal-time table: no fit for")
    elif spp is not None:
        parts += [f"No equal-time table: no method but the noisy input has a finished cell at "
                  f"{spp} spp.", ""]

    for other in extra_sweeps(results, sweep_dir):
        parts += other_sweep_md(results, other, rank_by=rank_by)

    stress = results / "stress.md"
    if stress.exists():
        text = stress.read_text(encoding="utf-8").splitlines()
        body = [ln for ln in text[2:] if not ln.startswith("## Details")]
        cut = body.index("## Details") if "## Details" in body else len(body)
        parts += ["## Stress test", ""] + body[:cut] + ["Details: [stress.md](stress.md)", ""]

    bench = speed_md(results)
    if bench:
        parts += ["## Speed benchmarks", "", bench, ""]

    extra = sorted(p for p in results.glob("*.md") if p.name not in ("README.md", "stress.md"))
    if extra:
        parts += ["## Per-method results", ""]
        parts += [f"- [{p.stem}]({p.name})" for p in extra] + [""]

    parts += ["## Metric definitions", "", metric_definitions_md(), ""]
    if isinstance(info.get("machine"), dict):
        parts += ["## Environment", "", machine_md(info["machine"]), ""]
    return "\n".join(parts)


def extra_sweeps(results: Path, main: Path) -> list[Path]:
    """Sweep folders beside the main one (``results/sweep-*`` holding a ``sweep.json``): sweeps
    whose settings differ, such as sequence scenes at 1 spp or transient videos."""
    return sorted(p.parent for p in results.glob("sweep-*/sweep.json")
                  if p.parent.resolve() != main.resolve())


def scene_columns(cells: list[dict]) -> dict[str, tuple[str, ...]]:
    """The headline columns of each sequence or transient scene of ``cells`` (a sequence's
    temporal metrics; :func:`dbench.report.verdicts.headline_columns`): a sweep's scenes may be
    of every kind, and its headline shows each with its own."""
    out = {}
    for c in cells:
        scene = str(c.get("scene"))
        if c.get("frames"):
            out[scene] = SEQUENCE_HEADLINE
        elif scene not in out and _is_transient(scene):
            out[scene] = TRANSIENT_HEADLINE
    return out


def _is_transient(scene: str) -> bool:
    try:
        from ..datasets.scenes import catalogue

        return catalogue.get(scene).kind == "transient"
    except Exception:  # noqa: BLE001 - an unknown scene name is not a transient one
        return False


def other_sweep_md(results: Path, sweep_dir: Path, rank_by: str = "relmse") -> list[str]:
    """A section for one extra sweep: its settings, the headline per scene at its spp (with
    intervals and the reference per cell), problems, and convergence tables."""
    info, cells, problems = load_sweep(sweep_dir)
    config = _config(info)
    df = tables.cells_frame(cells)
    status = verdicts.grid_status(config, cells)
    rel = Path(sweep_dir).relative_to(results).as_posix()
    sequence = any(c.get("frames") for c in cells)
    transient = any(_is_transient(str(c.get("scene"))) for c in cells)
    extras = []
    if config.get("frames"):
        extras.append(f"first {counted(config['frames'], 'frame')}")
    if config.get("bins"):
        extras.append(f"{config['bins']} time bins")
    if wall_text(info, cells):
        extras.append(wall_text(info, cells))
    parts = [f"## Sweep {markdown_code(rel)}", "", settings_line(config, df, status, rel, extras) +
             (" Sequences: each frame denoised once, in order; metrics are means over the "
              "frames after the 8-frame warm-up (all of a sequence of 8 or fewer); `t_rmse`"
              " / `tPSNR` score frame-to-frame differences." if sequence else "") +
             (" Transient videos: RMSE and relMSE over every voxel; SSIM and FLIP on the "
              "time-integrated image." if transient else ""), ""] + run_notes_md(info)
    skipped = sorted({str(c.get("method")) for c in cells if c.get("status") == "skipped"})
    if skipped:
        parts += ["Not applicable: " + ", ".join(map(markdown_text, skipped)) + ".", ""]
    lines = [ln for ln in problems_md(cells, problems, status["missing"])
             if not ln.startswith("- skipped ")]
    parts += lines + ([""] if lines else []) + input_warnings_md(cells, "### Input warnings")
    parts += nondeterministic_md(cells, "### Not reproducible")
    if status["mixed"]:
        parts += ["Mixed settings (cells computed with different settings or code, side by side "
                  "in the tables below):", ""] + mixed_md(status["mixed"]) + [""]
    rank = _pick_rank(df, rank_by)
    spp = verdicts.headline_spp(df.spp.unique()) if len(df) else None
    if spp is not None:
        cols = SEQUENCE_HEADLINE if sequence else (
            TRANSIENT_HEADLINE if transient else verdicts.HEADLINE)
        parts += [f"### Headline at {spp} spp", ""]
        parts += headline.headline_md(df, spp, rank, columns=cols, level="####")
        parts += reference_md(df)
    if sequence:
        parts += table31_md(df, cells)
    shown = ("rmse", "ssim", "t_rmse", "tpsnr", "cvvdp", "time_s") if sequence else (
        "rmse", "relmse", "ssim", "time_s")
    for metric in shown:
        if metric in df.columns and df[metric].notna().any():
            parts += [f"### {metric.upper()} (rows scene/method, columns spp)", ""
                      ] + tables.convergence_md(df, metric, cells)
    return parts


def speed_md(results: Path, method: str | None = None) -> str:
    """Tables of the JSON lines that `dbench bench ... --out results/bench_*.jsonl` appended."""
    import json

    rows_render, rows_method, rows_metrics, rows_files = [], [], [], []
    for path in sorted(results.glob("bench_*.jsonl")):
        for line in path.read_text(encoding="utf-8").splitlines():
            if not line.strip():
                continue
            r = json.loads(line)
            if r.get("benchmark") == "render" and method is None:
                rows_render.append({"scene": r["scene"], "res": r["res"], "spp": r["spp"],
                                    "plain_s": r["plain_s"], "samples_s": r["samples_s"],
                                    "samples+stats_s": r["samples_stats_s"],
                                    "stats/plain": r["ratio_stats_vs_plain"],
                                    "when": r["when"]})
            elif r.get("benchmark") == "metrics" and method is None:
                rows_metrics.append({"size": f"{r['width']}x{r['height']}",
                                     "plain_s": r["plain_s"], "judge_s": r["judge_s"],
                                     "judge/plain": r["ratio_judge_vs_plain"],
                                     "bootstrap_s": r["bootstrap_s"],
                                     "(judge+bootstrap)/plain":
                                         r["ratio_judge_bootstrap_vs_plain"],
                                     "when": r["when"]})
            elif r.get("benchmark") == "scene-file" and method is None:
                rows_files.append({"what": f"Cornell box as XML against the catalogue's, "
                                           f"{size_text(r['res'])} px, {r['spp']} spp",
                                   "ratio": r["ratio_xml_vs_catalogue"],
                                   "seconds": f"{r['xml_s']:.3g} / {r['catalogue_s']:.3g}",
                                   "when": r["when"]})
            elif r.get("benchmark") == "plugins" and method is None:
                rows_files.append({"what": "entry-point discovery at start-up",
                                   "ratio": float("nan"),
                                   "seconds": f"{r['discovery_s']:.3g} (built-ins "
                                              f"{r['builtins_s']:.3g})", "when": r["when"]})
            elif r.get("benchmark") == "method" and method in (None, r["method"]):
                fr = r.get("fast_vs_reference") or {}
                rows_method.append({"method": r["method"], "size": f"{r['width']}x{r['height']}",
                                    "time_s": r["time_s"], "oidn_s": r["oidn_time_s"],
                                    "vs_oidn": r["ratio_vs_oidn"],
                                    "fast/ref speedup": fr.get("speedup", float("nan")),
                                    "when": r["when"]})
    import pandas as pd

    out = []
    if rows_render:
        out += ["Statistics collection against a plain render of the same spp (same run):", "",
                markdown_table(pd.DataFrame(rows_render), ".3g"), ""]
    if rows_metrics:
        out += ["Metric time of one output: the judge (whole-image and surface metrics, "
                "top1_share, unbiased figures) and a one-seed block bootstrap, against the "
                "plain metrics it replaces (same run, same image):", "",
                markdown_table(pd.DataFrame(rows_metrics), ".3g"), ""]
    if rows_files:
        out += ["Scene files and plugins (`dbench bench scene-file`, `dbench bench plugins`; "
                "same run):", "", markdown_table(pd.DataFrame(rows_files), ".3g"), ""]
    if rows_method:
        out += ["Methods on a synthetic frame, against OIDN in the same run (median after "
                "warm-up; fast/ref = the method's fast path against its reference):", "",
                markdown_table(pd.DataFrame(rows_method), ".3g"), ""]
    return "\n".join(out)


def _statistical_checks(t, name: str) -> list[str]:
    """The issue's quality checks for one method column of the scene × spp RMSE table."""
    import numpy as np

    checks = []
    never_worse = (t[name] <= t["noisy"]).all()
    worse = t[t[name] > t["noisy"]]
    checks.append(f"- RMSE never above the noisy input's: {'yes' if never_worse else 'no'}"
                  + ("" if never_worse else " (" + ", ".join(
                      f"{markdown_text(r.scene)} {r.spp} spp" for r in worse.itertuples())
                      + ")"))
    mono = []
    for scene, g in t.groupby("scene"):
        r = g.sort_values("spp")[name].to_numpy()
        if not np.all(np.diff(r) < 0):
            mono.append(scene)
    checks.append("- RMSE decreasing as spp grows on every scene: "
                  + ("yes" if not mono else "no (" + ", ".join(map(markdown_text, mono)) + ")"))
    if "jbf" in t.columns:
        sub = t[t.scene.isin(["caustic", "mirrors"]) & (t.spp >= 64)]
        ok = (sub[name] < sub["jbf"]).all() if len(sub) else False
        checks.append("- Lower RMSE than jbf on caustic and mirrors at ≥ 64 spp: "
                      + ("yes" if ok else "no"))
    if "oidn" in t.columns:
        wins = int((t[name] < t["oidn"]).sum())
        checks.append(f"- Against oidn: lower RMSE in {wins} of {len(t)} (scene, spp) cells; "
                      "the table above shows which.")
    return checks


def statistical_md(df, sweep_dir: Path) -> str:
    """results/statistical.md: statistical vs noisy, jbf and oidn on every steady scene and spp,
    with the issue's quality checks evaluated on the table (not asserted: reported)."""
    names = [m for m in ("noisy", "jbf", "oidn", "statistical", "statistical+gate",
                         "statistical-gate")
             if m in set(df.method)]
    d = df[df.method.isin(names)]
    t = d.pivot_table(index=["scene", "spp"], columns="method", values="rmse", aggfunc="first")
    t = t[[m for m in names if m in t.columns]].reset_index()
    parts = ["# Statistical denoiser (steady): quality and speed", "",
             "Generated by `dbench report` from the sweep in "
             f"{markdown_code(sweep_dir.name + '/')}; "
             "RMSE on linear HDR values against the reference.", "",
             "## RMSE, scene × spp", "", markdown_table(t, ".4g"), ""]
    if "statistical" not in t.columns:
        return "\n".join(parts + ["(no statistical cells in this sweep)", ""])
    checks = []
    for name in [m for m in ("statistical", "statistical+gate", "statistical-gate")
                 if m in t.columns]:
        checks += [f"`{name}`:", ""] + _statistical_checks(t, name) + [""]
    parts += ["## Checks (issue 3)", ""] + checks
    timing = d.pivot_table(index="scene", columns="method", values="time_s", aggfunc="median")
    parts += ["## Denoise time (median over spp, seconds, at the sweep resolution)", "",
              markdown_table(timing.reset_index(), ".3g"), ""]
    bench = speed_md(sweep_dir.parent, "statistical")
    if bench:
        parts += ["## Speed at 1280×720", "", bench]
    return "\n".join(parts)

def publish(results: str | Path = "results", sweep_dir: str | Path | None = None,
            rank_by: str = "relmse") -> Path:
    results = Path(results)
    sweep_dir = Path(sweep_dir) if sweep_dir else results / "sweep"
    _, cells, _ = load_sweep(sweep_dir)
    df = tables.cells_frame(cells)
    if "statistical" in set(df.method):
        io.write_text(results / "statistical.md", statistical_md(df, sweep_dir))
    stale = sweep_dir / "pareto.png"  # replaced by the error_time_*.png figures
    if stale.exists():
        stale.unlink()
    if (results / "sweep-table31" / "sweep.json").is_file():
        table31_file(results, results / "sweep-table31")
    text = build_readme(results, sweep_dir, rank_by=rank_by)
    out = results / "README.md"
    io.write_text(out, text)
    sweeps = []
    for d in [sweep_dir, *extra_sweeps(results, sweep_dir)]:
        info, cells, _ = load_sweep(d)
        df, config = tables.cells_frame(cells), _config(info)
        # how the cells were timed stands on the results page too (side by side: contention)
        sweeps.append((d, cells, settings_line(config, df, verdicts.grid_status(config, cells),
                                               d.relative_to(results).as_posix(),
                                               side_by_side_text(cells), name=str)
                       if len(df) else "", *run_notes(info)))
    sweep_page(results, sweeps, rank_by=rank_by)  # last: it shows the figures just drawn
    return out
