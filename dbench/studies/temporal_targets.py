"""Issue 16's targets for the temporal filters, checked with paired intervals over many seeds.

The targets (results/temporal.md, "Which targets hold"): at 1 spp on ``orbit``, ``flicker`` and
``mirror-pan``, ``svgf``, ``asvgf`` and ``bmfr`` each below the noisy input and below
``accumulate`` in RMSE over surface pixels and in relMSE; A-SVGF below SVGF over the 5 frames
from ``flicker``'s light switch; A-SVGF's temporal error ``t_rmse`` on ``orbit`` no worse than
SVGF's.

Every comparison is paired seed by seed (docs/judging.md §3: the methods share each seed's noisy
input), as the mean difference and its 95 % t-interval, with a word: "below" or "above" when the
interval excludes 0, else "tied". Each is given over the first 3 seeds (what the sweeps and the
parameter study hold) and over all the seeds run, so that a tie of 3 seeds can be told apart from
a real one: the interval of 3 seeds is 4.3 standard errors wide either side, that of 10 seeds 2.3.

Three settings, each with one reference per scene and frame shared by the seeds:

* ``64`` — issue 16's: 64², ``orbit`` 48 frames with 4096-spp references, the others 24 frames
  with 256 (:data:`dbench.studies.temporal_study.SCENES`);
* ``128`` — the sequence sweep's: 128², 24 frames, 256-spp references;
* ``128x76`` — seed 001's Table 3.1 layout: 128×76, 24 frames, 1024-spp references.

Reproduce (about 4 minutes on 2 cores once the references are cached, the new seeds' 1-spp
frames rendered included)::

    python -m dbench.studies.temporal_targets --seeds 10 --out results/temporal_targets

writes ``targets.json`` (every seed's numbers) and ``targets.md`` (the tables).
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from ..options import Parser
from .temporal_study import SCENES as STUDY_SCENES
from .temporal_study import paired_text, paired_word
from .temporal_study import run as study_run

FILTERS = ("svgf", "asvgf", "bmfr")
VARIANTS = tuple((name, name, {}) for name in ("noisy", "accumulate") + FILTERS)
#: setting: (resolution as datasets.load takes it, {scene: (frames, reference spp)})
SETTINGS: dict[str, tuple[Any, dict[str, tuple[int, int]]]] = {
    "64": (64, dict(STUDY_SCENES)),
    "128": (128, {s: (24, 256) for s in STUDY_SCENES}),
    "128x76": ((128, 76), {s: (24, 1024) for s in STUDY_SCENES}),
}
#: the seeds the sweeps and the parameter study hold
FIRST_SEEDS = 3


def paired(rows_a: list[dict[str, Any]], rows_b: list[dict[str, Any]], metric: str,
           n_seeds: int | None = None) -> tuple[float, float, int] | None:
    """(mean, 95 % half-width, seeds) of ``metric`` of a minus b seed by seed over the seeds
    both hold (the first ``n_seeds`` of them when given); None with fewer than two."""
    from ..metrics.judge import t_interval

    a = {r["seed"]: r[metric] for r in rows_a if metric in r}
    b = {r["seed"]: r[metric] for r in rows_b if metric in r}
    seeds = sorted(set(a) & set(b))[:n_seeds]
    diffs = [a[s] - b[s] for s in seeds if math.isfinite(a[s]) and math.isfinite(b[s])]
    if len(diffs) < 2:
        return None
    mean, half = t_interval(diffs)
    return mean, half, len(diffs)


def verdict(result: tuple[float, float, int] | None, digits: int = 4) -> str:
    """``mean ± half (word)`` of :func:`paired`, "—" when there is none."""
    return "—" if result is None else paired_text(result[0], result[1], digits)


def run(setting: str, seeds: tuple[int, ...], progress: bool = False) -> list[dict[str, Any]]:
    """Rows of :func:`dbench.studies.temporal_study.run` for :data:`VARIANTS` on one setting."""
    res, scenes = SETTINGS[setting]
    rows = study_run(res, seeds, tuple(scenes), VARIANTS, progress=progress, settings=scenes)
    for r in rows:
        r["setting"] = setting
    return rows


def _digits(values: list[float]) -> int:
    """Decimals that show a difference of this size with two significant figures."""
    scale = max((abs(v) for v in values if math.isfinite(v)), default=1.0)
    return max(2, min(6, 2 - int(math.floor(math.log10(scale))) if scale > 0 else 4))


def tables(rows: list[dict[str, Any]]) -> str:
    """Markdown: per setting, each filter's paired differences to accumulate and to the noisy
    input on every scene (RMSE over surfaces, relMSE), over the first 3 seeds and over all;
    then A-SVGF against SVGF after flicker's light switch and in ``t_rmse`` on orbit."""
    out = []
    for setting in dict.fromkeys(r["setting"] for r in rows):
        sub = [r for r in rows if r["setting"] == setting]
        res, scenes = SETTINGS[setting]
        n_all = len({r["seed"] for r in sub})
        size = f"{res}²" if isinstance(res, int) else f"{res[0]}×{res[1]}"
        desc = ", ".join(f"`{s}` {f} frames, {spp}-spp references"
                         for s, (f, spp) in scenes.items())
        out += [f"### {size} ({desc}; 1 spp; {n_all} seeds)", "",
                f"Filter − accumulate, paired: over the first {FIRST_SEEDS} seeds | over "
                f"all {n_all}; and the word over all {n_all} against the noisy input.", "",
                "| scene | filter | RMSE (surfaces) − acc., 3 seeds | all seeds | "
                "relMSE − acc., 3 seeds | all seeds | below the noisy input (surfaces / relMSE) |",
                "|---|---|---|---|---|---|---|"]
        of = {(s, name): [r for r in sub if r["scene"] == s and r["method"] == name]
              for s in scenes for name in ("noisy", "accumulate") + FILTERS}
        for scene in scenes:
            for name in FILTERS:
                cells = []
                for metric in ("rmse_surface", "relmse"):
                    results = [paired(of[scene, name], of[scene, "accumulate"], metric, n)
                               for n in (FIRST_SEEDS, None)]
                    d = _digits([x[1] for x in results if x is not None])
                    cells += [verdict(x, d) for x in results]
                noisy = [paired(of[scene, name], of[scene, "noisy"], m)
                         for m in ("rmse_surface", "relmse")]
                words = " / ".join("—" if x is None else paired_word(x[0], x[1]) for x in noisy)
                out.append(f"| {scene} | {name} | " + " | ".join(cells) + f" | {words} |")
        out.append("")
        if "flicker" in scenes:
            x = paired(of["flicker", "asvgf"], of["flicker", "svgf"], "rmse_after_change")
            out.append(f"* A-SVGF − SVGF over the 5 frames from `flicker`'s light switch (RMSE), "
                       f"{n_all} seeds: {verdict(x)}")
        if "orbit" in scenes:
            x = paired(of["orbit", "asvgf"], of["orbit", "svgf"], "t_rmse")
            out.append(f"* A-SVGF − SVGF in `t_rmse` on `orbit`, {n_all} seeds: "
                       f"{verdict(x, 5)}")
        out.append("")
    return "\n".join(out)


def build_parser() -> Parser:
    """The options of :func:`main` (each single-valued one given at most once)."""
    ap = Parser(prog="python -m dbench.studies.temporal_targets",
                description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="results/temporal_targets", help="folder of "
                    "targets.json and targets.md")
    ap.add_argument("--seeds", type=int, default=10, help="seeds 0 … N−1 (at least 3)")
    ap.add_argument("--settings", default=",".join(SETTINGS),
                    help=f"comma-separated, of {', '.join(SETTINGS)}")
    return ap


def main(argv: list[str] | None = None) -> int:
    ap = build_parser()
    args = ap.parse_args(argv)
    from ..io import write_json, write_text

    chosen = [s for s in args.settings.split(",") if s]
    bad = [s for s in chosen if s not in SETTINGS]
    if bad or not chosen:
        ap.error(f"--settings: expected some of {', '.join(SETTINGS)}, got {args.settings!r}")
    if args.seeds < FIRST_SEEDS:
        ap.error(f"--seeds: expected an integer >= {FIRST_SEEDS}, got {args.seeds}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = [r for s in chosen for r in run(s, tuple(range(args.seeds)), progress=True)]
    write_json(out / "targets.json", {"seeds": args.seeds, "rows": rows})
    write_text(out / "targets.md", tables(rows))
    print(f"wrote {out / 'targets.md'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
