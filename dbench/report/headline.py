"""The headline of a scene: rows ranked by the ranking metric, ``mean ± interval`` entries and
the verdict words, one form for ``report.md`` (dbench/report/run_report.py), the sweep's README
(dbench/report/publish.py), the viewer (dbench/report/html.py) and the terminal
(dbench/report/terminal.py), so that all four say the same thing (README.md, "Usage").

Intervals, ties and rankings are :mod:`dbench.report.verdicts`'; this module only arranges them.

Verdict words name every headline metric on which a method is worse than the noisy input, with
the size of the loss: the method's mean over the noisy input's (``rmse 11.8×``; for PSNR and
tPSNR, a log scale, the difference in dB; ColorVideoVDP: in JOD), and, said once at the end, the losses the
intervals cannot tell from none ("(tied: intervals overlap on rmse, flip)"). Beside a whole-image loss stands the same metric over
surface pixels (``<metric>_surface``, README.md "Metrics"): where that is no worse than the
noisy input's, the loss comes from lights seen directly or in mirrors, and the words say so
("rmse 11.8×, from directly seen lights: rmse_surface 0.9×"); beside a surface loss stands the
whole-image figure that hides it.
"""
from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

import pandas as pd

from .formats import markdown_table, markdown_text
from .tables import unshown_md
from .verdicts import (HEADLINE, NOISY, TIE_WORDS, ci_kind_text, finite, fmt_value, half_width,
                       higher_is_better, marked, num, rank_groups, ranking_line, reference_text,
                       tie)

SURFACE = "_surface"
#: Columns that are costs, not losses: never a verdict.
COSTS = frozenset({"time_s", "time_s_iqr", "render_s", "total_s", "method"})
#: Metrics on a log scale: their loss is a difference (dB), not a ratio.
DECIBELS = frozenset({"psnr", "psnr_surface", "tpsnr"})
#: Metrics on a perceptual scale: their loss is a difference in just-objectionable differences.
JODS = frozenset({"cvvdp"})

#: What the verdict column says, for the notes under the tables.
VERDICT_NOTE = ("`verdict` names every headline metric on which a method is worse than the "
                "noisy input, with the size of the loss (its mean / the noisy input's; PSNR, "
                "SSIM and other scores where higher is better: the difference, in dB for PSNR) "
                "and, at the end, the losses the intervals cannot tell "
                "from none (`tied: …`); beside a whole-image loss, the same metric over surface "
                "pixels: no worse than the noisy input there means the loss comes from lights "
                "seen directly or in mirrors.")


def timing_words(repeats: Any, seeds: Any) -> str:
    """The calls ``time_s`` is the median of, for the notes under the tables: each seed is
    timed alone, one warm-up call and then ``repeats`` calls, and the median is over the calls
    of every seed together (``run_cell`` in dbench/run/harness.py; docs/metrics.md §1), so with
    3 seeds and ``--repeats 1`` it is the median of 3 calls, not of 1."""
    n = seeds if isinstance(seeds, int) and not isinstance(seeds, bool) else 1
    if not isinstance(repeats, int) or isinstance(repeats, bool):
        return "the timed calls after one warm-up (how many is not recorded)"
    if n <= 1:
        return f"{repeats} timed call{'' if repeats == 1 else 's'} after one warm-up"
    return (f"{repeats * n} timed calls ({repeats} per seed × {n} seeds, each seed after one "
            "warm-up call)")


def flag_metrics(columns: Sequence[str], rank_by: str) -> list[str]:
    """The metrics a verdict looks at: the ranking metric, then every metric column (time is
    a cost, not a loss)."""
    return [c for c in dict.fromkeys([rank_by, *columns]) if c not in COSTS]


def loss_size(value: float, noisy: float, metric: str) -> str:
    """``11.8×`` (value / noisy) for an error, or the difference for a score where higher is
    better: ``−2.6 dB`` for PSNR-like metrics, ``−0.15`` for SSIM (signed, in [−1, 1], so a
    ratio of two SSIMs means nothing and flips with their signs)."""
    if metric in DECIBELS:
        return f"{value - noisy:+.2g} dB".replace("-", "−")
    if metric in JODS:
        return f"{value - noisy:+.2g} JOD".replace("-", "−")
    if higher_is_better(metric):
        return f"{value - noisy:+.2g}".replace("-", "−")
    if noisy == 0:
        return f"{value:.3g} (noisy 0)"
    ratio = value / noisy
    # two figures say the size; more only where fewer would round a loss to "1×" (a flagged
    # loss of 0.25 % reads 1.0025×, never 1×)
    text = f"{ratio:.2g}" if 0.1 <= ratio < 10 else f"{ratio:.3g}"
    digits = 3
    while float(text) == 1 != ratio and digits <= 6:
        text, digits = f"{ratio:.{digits}g}", digits + 1
    return f"{text}×"


def _worse(r: Any, base: Any, metric: str) -> bool | None:
    """Whether row ``r`` is worse than ``base`` on ``metric``; None where either lacks it."""
    if metric not in r.index or not (finite(r[metric]) and finite(base[metric])):
        return None
    sign = -1.0 if higher_is_better(metric) else 1.0
    return sign * (float(r[metric]) - float(base[metric])) > 0


def _size(r: Any, base: Any, metric: str) -> str:
    return f"{metric} {loss_size(float(r[metric]), float(base[metric]), metric)}"


def _loss_words(r: Any, base: Any, metrics: Sequence[str]) -> tuple[list[str], str]:
    """One phrase per metric of ``metrics`` on which ``r`` is worse than ``base``, and how
    those the intervals cannot tell apart tie ("" when none does)."""
    words, ties = [], {}
    for metric in metrics:
        if not _worse(r, base, metric):
            continue
        how = tie(r, base, metric)
        if how:
            ties.setdefault(how, []).append(metric)
        text = _size(r, base, metric)
        if metric.endswith(SURFACE):
            whole = metric[:-len(SURFACE)]
            if _worse(r, base, whole) is False:  # the whole image hides a loss on surfaces
                text += f" (whole image {_size(r, base, whole)[len(whole) + 1:]})"
        else:
            surface = _worse(r, base, metric + SURFACE)
            if surface is False:
                text += f", from directly seen lights: {_size(r, base, metric + SURFACE)}"
            elif surface and metric + SURFACE not in metrics:
                text += f" (surfaces {_size(r, base, metric + SURFACE)[len(metric) + 9:]})"
        words.append(text)
    tied = sum(len(ms) for ms in ties.values())
    if len(ties) == 1 and tied == len(words):  # one way for every loss: said once
        return words, TIE_WORDS[next(iter(ties))]
    return words, "; ".join(f"{TIE_WORDS[how]} on {', '.join(ms)}" for how, ms in ties.items())


def worse_than_noisy(d: pd.DataFrame, metrics: Sequence[str]) -> dict[str, str]:
    """label → words for each method whose mean is worse than the noisy input's on any of
    ``metrics``, with the size of each loss (module docstring)."""
    noisy = d[d["method"] == NOISY]
    if noisy.empty:
        return {}
    base = noisy.iloc[0]
    out = {}
    for _, r in d.iterrows():
        if r["method"] == NOISY:
            continue
        words, ties = _loss_words(r, base,
                                  [m for m in dict.fromkeys(metrics) if m not in COSTS])
        if words:
            out[str(r["method"])] = ("worse than noisy on " + "; ".join(words)
                                     + (f" (tied: {ties})" if ties else ""))
    return out


def verdict_words(d: pd.DataFrame, columns: Sequence[str], rank_by: str) -> dict[str, str]:
    """label → the verdict of every row: "noisy input", the losses to it
    (:func:`worse_than_noisy` over :func:`flag_metrics`) and how many non-finite values its
    outputs held (its metrics are then NaN); "" for a method with nothing to say."""
    flags = worse_than_noisy(d, flag_metrics(columns, rank_by))
    out = {}
    for _, r in d.iterrows():
        lab = str(r["method"])
        words = ["noisy input" if lab == NOISY else flags.get(lab, "")]
        nonfinite = num(r["n_nonfinite"]) if "n_nonfinite" in d.columns else float("nan")
        if math.isfinite(nonfinite) and nonfinite > 0:
            n = int(nonfinite)
            words.append(f"{n} non-finite output value{'s' if n != 1 else ''}")
        apart = num(r["nondeterministic_abs"]) if "nondeterministic_abs" in d.columns else \
            float("nan")
        if not math.isnan(apart):  # its calls on one input differed: one call's numbers
            words.append("not reproducible: calls on one input gave different outputs ("
                         + difference_text(apart, num(r["nondeterministic_rel"])) + ")")
        out[lab] = "; ".join(w for w in words if w)
    return out


def difference_text(max_abs: float, max_rel: float) -> str:
    """``largest difference 3.1e-05, 0.002 % of the output's largest value``: how far apart
    two outputs of one input are (dbench.run.inputs.output_difference)."""
    if not math.isfinite(max_abs):
        return "a value finite in one output is not in the other, or their shapes differ"
    text = f"largest difference {max_abs:.2g}"
    return text + (f", {max_rel * 100:.2g} % of the output's largest value"
                   if math.isfinite(max_rel) else "")


def nondeterminism_text(label: str, nd: Mapping[str, Any]) -> str:
    """The line ``dbench run`` prints, and its report's notes hold, for a method whose calls
    on one input gave different outputs (a cell's ``nondeterministic``,
    dbench/run/harness.py; README.md "Usage")."""
    seeds = nd.get("seeds") or []
    where = "; " + ", ".join(p for p in (
        f"seed{'s' if len(seeds) != 1 else ''} {', '.join(map(str, seeds))}" if seeds else "",
        str(nd.get("calls") or "")) if p)
    return (f"{label}: two calls on the same input gave different outputs ("
            f"{difference_text(num(nd.get('max_abs_diff')), num(nd.get('max_rel_diff')))}"
            f"{where if where != '; ' else ''}): its numbers are those of "
            f"{nd.get('scored') or 'the last call'} and are not reproducible")


#: What the sweep's README and page say above :func:`nondeterministic_lines`.
NONDETERMINISTIC_INTRO = ("Cells whose method gave different outputs in two calls on the same "
                          "input (compared exactly, NaN in the same places equal; README.md, "
                          "\"Usage\"), as {run} prints it:")


def nondeterministic_lines(cells: Sequence[dict]) -> list[str]:
    """``scene at 4, 16 spp: label: two calls on the same input gave different outputs …``
    (:func:`nondeterminism_text`) for each scene and method label whose finished cells record
    ``nondeterministic``, at any spp (a headline's verdicts stand at one spp only), with the
    largest differences over them; [] where no cell does (older cells record nothing)."""
    found: dict[tuple[str, str], tuple[list[int], dict[str, Any]]] = {}
    for c in cells:
        nd = c.get("nondeterministic") if isinstance(c, dict) and c.get("status") == "ok" \
            else None
        if not isinstance(nd, dict):
            continue
        spp, merged = found.setdefault((str(c.get("scene")), str(c.get("method"))), ([], {}))
        spp += [c["spp"]] if isinstance(c.get("spp"), int) else []
        for key in ("max_abs_diff", "max_rel_diff"):
            merged[key] = max(num(merged.get(key, 0.0)), num(nd.get(key)))
        seeds = merged.setdefault("seeds", [])
        seeds += [s for s in nd.get("seeds") or [] if s not in seeds]
        merged.update({k: nd[k] for k in ("calls", "scored") if nd.get(k)})
    return [f"{scene} at {', '.join(map(str, sorted(set(spp))))} spp: "
            + nondeterminism_text(label, nd) for (scene, label), (spp, nd) in sorted(found.items())]


def ranked_labels(d: pd.DataFrame, rank_by: str) -> list[tuple[int | None, str]]:
    """(place, label) best first: tied labels share a place; labels without a value of
    ``rank_by`` come last, sorted, with place None."""
    out: list[tuple[int | None, str]] = []
    for place, group in enumerate(rank_groups(d, rank_by), start=1):
        out += [(place, lab) for lab in group]
    ranked = {lab for _, lab in out}
    return out + [(None, lab) for lab in sorted(set(map(str, d["method"])) - ranked)]


def scene_table(d: pd.DataFrame, columns: Sequence[str], rank_by: str) -> pd.DataFrame:
    """Rows ranked by ``rank_by``; entries ``mean ± ci``, best and tied in bold, and the
    verdict column (:func:`verdict_words`)."""
    cols = [c for c in dict.fromkeys([*columns, rank_by]) if c in d.columns]
    bold = {c: marked(d, c, exclude=(NOISY,) if c == "time_s" else ()) for c in cols}
    verdict = verdict_words(d, cols, rank_by)
    by_label = {str(r["method"]): r for _, r in d.iterrows()}
    rows = []
    for _, lab in ranked_labels(d, rank_by):
        r = by_label[lab]
        row = {"method": lab}
        for c in cols:
            text = fmt_value(num(r[c]), half_width(r, c))
            row[c] = f"**{text}**" if lab in bold[c] else text
        row["verdict"] = verdict[lab]
        rows.append(row)
    return pd.DataFrame(rows, columns=["method", *cols, "verdict"])


def scene_block_md(d: pd.DataFrame, rank_by: str, columns: Sequence[str] = HEADLINE,
                   heading: str | None = None, asked: str | None = None) -> list[str]:
    """Markdown for one scene at one spp: ranking line (``asked``: the metric asked for, named
    where ``rank_by`` stands in for it), intervals, reference, table."""
    parts = [heading, ""] if heading else []
    parts += [f"Ranking by {ranking_line(d, rank_by, asked, name=markdown_text)}.", "",
              f"{ci_kind_text(d).capitalize()}; {reference_text(d, markdown_text)}.", "",
              markdown_table(scene_table(d, columns, rank_by)), ""]
    return parts


def headline_md(df: pd.DataFrame, spp: int | None, rank_by: str = "relmse",
                columns: Sequence[str] = HEADLINE, level: str = "###",
                scene_columns: Mapping[str, Sequence[str]] | None = None) -> list[str]:
    """Per scene at ``spp``: the ranking line and the ``mean ± ci`` table (columns that no
    cell records are left out and named). ``scene_columns``: the columns of the scenes whose
    kind has others (a sequence's temporal metrics, :func:`verdicts.headline_columns`)."""
    d = df[df["spp"] == spp] if spp is not None else df.iloc[0:0]
    if d.empty:
        return ["(no finished cells at this spp)", ""]
    scenes = sorted(set(map(str, df["scene"])))
    shown_of = {}
    for scene in scenes:
        g = d[d["scene"] == scene]
        shown_of[scene] = [c for c in (scene_columns or {}).get(scene, columns)
                           if c in g.columns and g[c].map(finite).any()]
    asked = dict.fromkeys(c for s in scenes for c in (scene_columns or {}).get(s, columns))
    absent = [c for c in asked if not any(c in shown_of[s] for s in scenes)]
    parts = [("**Bold**: the best entry of a column on the scene and every entry tied with it "
              "(the paired difference over the seeds both cells hold includes 0; without common "
              "seeds, the intervals overlap or one is missing, `± n/a`). Entries are mean ± 95 % "
              "half-width; `time_s` is "
              "the median denoise time ± half its IQR (the noisy input is not a candidate for "
              f"the fastest). Rows ranked by `{rank_by}`; " + VERDICT_NOTE), ""]
    parts += unshown_md(df, absent)
    for scene in scenes:
        g = d[d["scene"] == scene]
        if len(g):
            parts += scene_block_md(g, rank_by, shown_of[scene],
                                    heading=f"{level} {markdown_text(scene)}")
            continue
        # a scene without cells at this spp is named, never left out of "every scene"
        has = sorted({int(v) for v in df.loc[df["scene"] == scene, "spp"]})
        parts += [f"{level} {markdown_text(scene)}", "", f"No finished cell at {spp} spp (its "
                  f"cells are at {', '.join(map(str, has))} spp: the convergence tables "
                  "below).", ""]
    return parts


__all__ = ["VERDICT_NOTE", "NONDETERMINISTIC_INTRO", "difference_text", "nondeterminism_text",
           "nondeterministic_lines", "timing_words", "flag_metrics", "loss_size",
           "worse_than_noisy", "verdict_words", "ranked_labels", "scene_table", "scene_block_md",
           "headline_md"]
