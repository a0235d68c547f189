"""``dbench report`` on sweep folders at the edges (README.md, "Usage", the ``dbench report``
paragraph): no finished cell, one cell, one method, every value NaN; each is a README that
says what is there, with no traceback, no empty figure and no misleading word."""
from __future__ import annotations

import json
import math

from dbench.cli import main
from sweep_cells import ok_cell  # tests/sweep_cells.py


def _cell(scene: str, spp: int, method: str, err: float = 0.03) -> dict:
    return ok_cell(scene, spp, method, err)


def _report(tmp_path, cells, scenes, methods, spp, **info) -> str:
    """README.md of ``dbench report`` over a sweep folder holding ``cells`` (``info``: more
    of sweep.json, its runs)."""
    sweep = tmp_path / "results" / "sweep"
    sweep.mkdir(parents=True, exist_ok=True)
    (sweep / "sweep.json").write_text(json.dumps({"config": {
        "labels": methods, "methods": methods, "scenes": scenes, "spp": spp, "res": 16,
        "seeds": 1, "seed": 0, "repeats": 1}, **info}))
    for c in cells:
        p = sweep / "cells" / c["scene"] / f"{c['spp']:05d}spp" / f"{c['method']}.json"
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(json.dumps(c))
    assert main(["report", "--results", str(tmp_path / "results")]) == 0
    return (tmp_path / "results" / "README.md").read_text(encoding="utf-8")


def test_a_sweep_without_finished_cells_draws_no_empty_figure_and_says_why(tmp_path):
    sweep = tmp_path / "results" / "sweep"
    sweep.mkdir(parents=True)
    (sweep / "convergence.png").write_bytes(b"an earlier report's figure")
    failed = [{"status": "error", "scene": "cornell", "spp": 4, "method": m, "error": "boom"}
              for m in ("noisy", "jbf")]
    md = _report(tmp_path, failed, ["cornell"], ["noisy", "jbf"], [4])
    assert list(sweep.glob("*.png")) == []
    assert "![convergence]" not in md
    assert "No convergence figure: no finished cell records a finite rmse" in md
    page = (tmp_path / "results" / "index.html").read_text(encoding="utf-8")
    assert ".png" not in page
    # no table of headers alone is written, nor linked
    assert ".csv)" not in md and not list(sweep.glob("tables/convergence_*.csv"))


def test_a_sweep_whose_every_value_is_nan_is_reported_without_a_figure(tmp_path):
    cells = [_cell("cornell", s, m, math.nan) for s in (4, 16) for m in ("noisy", "jbf")]
    md = _report(tmp_path, cells, ["cornell"], ["noisy", "jbf"], [4, 16])
    assert "No convergence figure" in md
    assert not (tmp_path / "results" / "sweep" / "convergence.png").exists()
    # the cells record every metric, as NaN: never "not recorded", never a check that
    # could not be made said as passed
    assert "Not recorded in these cells" not in md and "is not recorded in these cells" not in md
    assert "Not finite in any cell that records it (NaN or Inf): rmse, rmse_surface" in md
    assert "(`relmse` is not finite in any cell: ranked by `rmse`.)" in md
    assert "No cell's reference error exceeds" not in md
    assert "the reference's own noise cannot be checked here" in md


def test_cells_whose_error_is_nan_are_not_counted_as_a_checked_reference(tmp_path):
    cells = [_cell("cornell", 4, "noisy"), _cell("cornell", 4, "jbf", math.nan)]
    md = _report(tmp_path, cells, ["cornell"], ["noisy", "jbf"], [4])
    assert ("No cell's reference error exceeds 10 % of the method's (1 cell without a finite "
            "error not checked).") in md


def test_one_cell_is_one_scene_one_label_one_cell_in_the_words(tmp_path):
    cell = {**_cell("cornell", 4, "noisy"), "ref_render_s": 2.0}
    md = _report(tmp_path, [cell], ["cornell"], ["noisy"], [4],
                 runs=[{"wall_s": 3, "cells": 1}])
    settings = next(ln for ln in md.splitlines() if ln.startswith("Sweep `sweep`"))
    assert "1 scene (cornell) × 1 method label × spp 4" in settings
    assert "1 seed (first seed 0)" in settings
    assert "wall time 3 s for the last 1 cell computed (1 run), 1 reference rendered" in settings
    assert "the machine the cells were timed on is not recorded (1 cell," in settings
    assert not any(w in settings for w in ("1 scenes", "1 method labels", "1 cells"))


def test_a_sweep_without_finished_cells_says_so_instead_of_a_headline_of_none(tmp_path):
    skipped = [{"status": "skipped", "scene": "cornell", "spp": 4, "method": "svgf",
                "reason": "sequence only"}]
    md = _report(tmp_path, skipped, ["cornell"], ["svgf"], [4])
    assert "## Headline\n\nNo finished cell: nothing to rank" in md
    # no cell to say what it records: never "at None spp", never "older format"
    assert "None" not in md and "older format" not in md and "is not recorded in" not in md


def test_a_noisy_error_flat_over_spp_gives_no_equal_spp_and_no_overflow():
    """Cells whose noisy error is the same at every spp (the fit's slope is −5e-16, not 0):
    no spp of plain rendering reaches a method's error, said as such, never "inf" after an
    overflow warning."""
    import warnings

    from dbench.report import tables

    cells = [_cell("cornell", s, m, 0.05 if m == "noisy" else 0.03)
             for s in (4, 16) for m in ("noisy", "jbf")]
    df = tables.cells_frame(cells)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        eq = tables.equal_time_md(df, 16)
        gaps = tables.equal_time_gaps(df)
    assert "equal_rmse_spp" not in eq.columns
    assert "cornell on rmse (the noisy input's rmse does not fall as spp grows" in gaps[0]


def test_the_equal_time_view_without_a_figure_says_why_in_one_line(tmp_path):
    """One method only: no table, one line; one spp only: no table of times alone (the
    equal spp needs the noisy input at two spp), the reason instead."""
    md = _report(tmp_path / "a", [_cell("cornell", s, "noisy", 0.1 / s) for s in (4, 16)],
                 ["cornell"], ["noisy"], [4, 16])
    assert "No equal-time table: no method but the noisy input has a finished cell at 16 spp." \
        in md
    cells = [_cell("cornell", 4, m, e) for m, e in (("noisy", 0.05), ("jbf", 0.03))]
    md = _report(tmp_path / "b", cells, ["cornell"], ["noisy", "jbf"], [4])
    assert "| scene | method | total_s |" not in md
    assert ("No equal-time table: no fit for cornell on rmse (fewer than two spp of the noisy "
            "input)") in md


def test_a_sequence_scene_in_the_main_sweep_shows_its_temporal_metrics(tmp_path):
    """A sweep of a sequence scene beside a steady one: each scene's headline table has its
    kind's columns (``t_rmse``, ``tpsnr`` for the sequence), as a sweep of its own shows."""
    seq = [{**_cell("orbit", 4, m, e), "frames": 2, "t_rmse": e, "t_rmse_ci": 0.001,
            "tpsnr": 30.0, "tpsnr_ci": 0.1} for m, e in (("noisy", 0.05), ("svgf", 0.03))]
    steady = [_cell("cornell", 4, m, e) for m, e in (("noisy", 0.05), ("svgf", 0.03))]
    md = _report(tmp_path, seq + steady, ["orbit", "cornell"], ["noisy", "svgf"], [4])

    def header(scene: str) -> str:
        block = md[md.index(f"### {scene}\n"):]
        return next(ln for ln in block.splitlines() if ln.startswith("| method |"))

    assert "| t_rmse | tpsnr |" in header("orbit")
    assert "t_rmse" not in header("cornell") and "| flip |" in header("cornell")
    assert "Not recorded in these cells: cvvdp." in md


def test_a_sweep_of_one_frame_says_one_frame(tmp_path):
    from dbench.report import publish

    sweep = tmp_path / "results" / "sweep-seq"
    p = sweep / "cells" / "orbit" / "00001spp" / "noisy.json"
    p.parent.mkdir(parents=True)
    p.write_text(json.dumps({**_cell("orbit", 1, "noisy"), "frames": 1}))
    (sweep / "sweep.json").write_text(json.dumps({"config": {
        "labels": ["noisy"], "methods": ["noisy"], "scenes": ["orbit"], "spp": [1], "res": 16,
        "seeds": 1, "seed": 0, "repeats": 1, "frames": 1}}))
    text = "\n".join(publish.other_sweep_md(tmp_path / "results", sweep))
    assert "first 1 frame;" in text and "1 frames" not in text


def test_a_method_that_does_not_apply_reads_n_a_in_the_convergence_tables(tmp_path):
    skipped = [{"status": "skipped", "scene": "mirrors", "spp": s, "method": "svgf",
                "reason": "sequence only"} for s in (4, 16)]
    cells = [_cell(sc, s, m) for sc in ("cornell", "mirrors") for s in (4, 16)
             for m in ("noisy", "svgf") if (sc, m) != ("mirrors", "svgf")]
    del cells[1]  # cornell svgf at 4 spp: no cell
    md = _report(tmp_path, cells + skipped, ["cornell", "mirrors"], ["noisy", "svgf"], [4, 16])
    table = md[md.index("### RMSE (rows"):md.index("### RELMSE (rows")]
    assert "| mirrors | svgf | n/a | n/a |" in table  # does not apply
    assert "| cornell | svgf | — | 0.03 ± 0.0003 |" in table  # no cell
    assert "n/a: the method does not apply to the scene (its cell is skipped, not run)" in table
