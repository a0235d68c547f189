"""A convergence entry without a number says why (README.md, "Usage", the ``dbench report``
paragraph): "—" only where the sweep holds no cell; a cell whose method's outputs held NaN or
Inf (its metrics are NaN, README.md "Metrics") says "no value (non-finite output)", in the
README's tables and on the results page, so a finished cell never reads as one not run."""
from __future__ import annotations

import math

from dbench.report import html, tables


def _cell(method: str, spp: int, rmse: float, nonfinite: int = 0) -> dict:
    return {"status": "ok", "scene": "cornell", "method": method, "base_method": method,
            "spp": spp, "res": 16, "n_seeds": 2, "rmse": rmse, "rmse_ci": 0.01,
            "relmse": rmse, "relmse_ci": 0.01, "time_s": 0.01, "n_nonfinite": nonfinite}


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
