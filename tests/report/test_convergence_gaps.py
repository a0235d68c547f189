"""A convergence entry without a number says why (README.md, "Usage", the ``dbench report``
paragraph): "—" only where the sweep holds no cell; a cell whose method's outputs held NaN or
Inf (its metrics are NaN, README.md "Metrics") says "no value (non-finite output)", in the
README's tables and on the results page, so a finished cell never reads as one not run; and
a report over fewer cells leaves no figure or table of the earlier ones."""
from __future__ import annotations

import math

from dbench.report import html, tables


def _cell(method: str, spp: int, rmse: float, nonfinite: int = 0) -> dict:
    return {"status": "ok", "scene": "cornell", "method": method, "base_method": method,
            "spp": spp, "res": 16, "n_seeds": 2, "rmse": rmse, "rmse_ci": 0.01,
            "relmse": rmse, "relmse_ci": 0.01, "time_s": 0.01, "render_s": 0.05 * spp,
            "n_nonfinite": nonfinite}


def test_a_cell_of_nonfinite_outputs_is_not_a_missing_cell():
    cells = [_cell("noisy", 4, 0.2), _cell("noisy", 16, 0.1),
             _cell("nan-out", 4, math.nan, nonfinite=3),  # ran, every metric NaN
             _cell("jbf", 16, 0.05)]                       # no 4-spp cell at all
    df = tables.cells_frame(cells)
    md = tables.convergence_table_md(df, "rmse").set_index("method")
    assert md.loc["nan-out", "4 spp"] == "no value (non-finite output)"
    assert md.loc["nan-out", "16 spp"] == "—"
    assert md.loc["jbf", "4 spp"] == "—" and md.loc["jbf", "16 spp"] == "0.05 ± 0.01"
    grid = html.grid_table(df, "rmse")
    text = {tuple(r[:2]): r[2:] for r in grid["text"]}
    assert text[("cornell", "nan-out")] == ["no value (non-finite output)", ""]
    assert text[("cornell", "jbf")] == ["", "0.05 ± 0.01"]


def test_a_report_of_fewer_cells_leaves_no_figure_or_table_of_the_earlier_ones(tmp_path):
    """``dbench report`` after cells were removed (a sweep started again in its folder): the
    error-against-time figure the README now says cannot be drawn, and the convergence CSV of a
    metric no cell records, are gone, not left with the earlier cells' numbers."""
    import pandas as pd

    from dbench.report import plots

    before = tables.cells_frame([_cell("noisy", 4, 0.2), _cell("noisy", 16, 0.1)])
    before["rmse_surface"], before["rmse_surface_ci"] = 0.05, 0.01
    out = tmp_path / "tables"
    written = tables.write_tables(before, out)
    figure = tmp_path / "error_time_rmse_surface.png"
    assert plots.error_time_plot(before, "rmse_surface", figure) and figure.is_file()
    assert "convergence_rmse_surface" in written
    after = tables.cells_frame([])
    assert not plots.error_time_plot(after, "rmse_surface", figure)
    assert not figure.exists()
    written = tables.write_tables(after, out)
    assert "convergence_rmse_surface" not in written
    assert not (out / "convergence_rmse_surface.csv").exists()
    left = {p.name for p in out.glob("convergence_*.csv")}
    assert left == {p.name for k, p in written.items() if k.startswith("convergence_")}
    assert all(pd.read_csv(out / n).empty for n in left)


def test_a_scene_without_cells_at_the_headline_spp_is_named_in_the_headline():
    """"every method × every scene at 64 spp": a scene whose cells are all at other spp gets its
    heading and a line saying where its cells are, never a silent gap."""
    from dbench.report import headline

    cells = [_cell(m, spp, 0.1 / spp) for m in ("noisy", "jbf") for spp in (4, 64)]
    cells += [{**_cell(m, 4, 0.05), "scene": "mirrors"} for m in ("noisy", "jbf")]
    text = "\n".join(headline.headline_md(tables.cells_frame(cells), 64))
    assert "### cornell" in text and "| jbf |" in text
    assert ("### mirrors\n\nNo finished cell at 64 spp (its cells are at 4 spp: the "
            "convergence tables below).") in text
