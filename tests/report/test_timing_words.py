"""The note under the tables says how many calls ``time_s`` is the median of: every seed is
timed alone after its own warm-up and the calls of all seeds are pooled
(dbench/run/harness.py, ``run_cell``), so ``--seeds 3 --repeats 1`` is a median of 3 calls and
the ``±`` beside it is their spread (README.md, "Usage"; docs/metrics.md §1)."""
from __future__ import annotations

import json

import pandas as pd

from dbench.report import headline, publish, run_report

SETTINGS = {"scene": "cornell", "kind": "steady", "spp": 4, "res": 16, "ref_spp": 64}
MACHINE = {"cpu": "c", "cores": 2, "gpu": "none", "python": "3", "platform": "p",
           "packages": {}}


def _cell(method: str, seeds: int, repeats: int) -> dict:
    c = {"status": "ok", "scene": "cornell", "method": method, "base_method": method,
         "spp": 4, "res": 16, "n_seeds": seeds, "seeds": list(range(seeds)),
         "ci_kind": f"t 95 % over {seeds} seeds", "ref_spp": 64, "ref_rmse": 0.01,
         "time_s": 0.01, "time_s_iqr": 0.002, "times_s": [0.01] * (seeds * repeats),
         "n_nonfinite": 0, "params": {}}
    for m, v in (("rmse", 0.1), ("relmse", 0.02), ("rmse_surface", 0.05), ("ssim", 0.8),
                 ("flip", 0.2), ("relmse_surface", 0.02)):
        c[m], c[m + "_ci"] = (v if method == "noisy" else v / 2), v / 100
    return c


def test_the_words_count_every_timed_call():
    assert headline.timing_words(5, 1) == "5 timed calls after one warm-up"
    assert headline.timing_words(1, 1) == "1 timed call after one warm-up"
    assert headline.timing_words(1, 3) == ("3 timed calls (1 per seed × 3 seeds, each seed "
                                           "after one warm-up call)")
    assert headline.timing_words(None, 3) == ("the timed calls after one warm-up (how many is "
                                              "not recorded)")


def test_run_report_counts_the_calls_of_every_seed():
    table = pd.DataFrame([{k: v for k, v in _cell(m, 3, 1).items()
                           if k not in ("seeds", "times_s", "params")}
                          for m in ("noisy", "jbf")])
    md = " ".join(run_report.run_report_md(table, {**SETTINGS, "repeats": 1}, MACHINE,
                                           {}).split())
    assert "`time_s` is the median denoise time over 3 timed calls (1 per seed × 3 seeds" in md
    assert "of 1 calls" not in md
    # the noisy input (fastest here) is not bold in time_s, and the note says so
    assert "the noisy input is not a candidate for the fastest `time_s`" in md


def _sweep_readme(tmp_path, **cell) -> str:
    sweep = tmp_path / "results" / "sweep"
    config = {"labels": ["noisy", "jbf"], "methods": ["noisy", "jbf"], "scenes": ["cornell"],
              "spp": [4], "res": 16, "seeds": 2, "seed": 0, "ref_spp": 64, "repeats": 5}
    sweep.mkdir(parents=True)
    (sweep / "sweep.json").write_text(json.dumps({"config": config, "machine": MACHINE}))
    for m in ("noisy", "jbf"):
        p = sweep / "cells" / "cornell" / "00004spp" / f"{m}.json"
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(json.dumps({**_cell(m, 2, 5), **cell}))
    return " ".join(publish.publish(tmp_path / "results").read_text().split())


def test_sweep_readme_counts_the_calls_of_every_seed(tmp_path):
    text = _sweep_readme(tmp_path)
    assert ("denoise time = median over 10 timed calls (5 per seed × 2 seeds, each seed after "
            "one warm-up call) (rendering excluded)") in text


def test_a_sequence_sweep_says_only_how_sequences_are_timed(tmp_path):
    """A sequence cell denoises each frame once (--repeats does not apply): its README speaks
    of the frames after the warm-up, never of timed calls."""
    text = _sweep_readme(tmp_path, frames=4)
    assert "timed call" not in text
    assert "time the median per frame after the 8-frame warm-up (all of a sequence" in text

