"""Plain table formats: pandas → CSV files (written atomically) and GitHub Markdown tables."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from .. import io


def write_csv(path: str | Path, table: pd.DataFrame) -> None:
    with io.atomic_path(path, suffix=".tmp.csv") as tmp:
        table.to_csv(tmp, index=False, float_format="%.6g", encoding="utf-8")


def markdown_cell(text: Any) -> str:
    """``text`` as one cell of a GitHub Markdown table: a ``|`` in a method or scene name (a
    plugin may register any name, README.md "Add your own denoiser") would end the cell and
    shift every number after it into the next column, so it is escaped (``\\|``, which GitHub
    shows as ``|``); a line break would end the row, so it becomes a space."""
    return " ".join(str(text).splitlines()).replace("|", "\\|")


def markdown_table(table: pd.DataFrame, floatfmt: str = ".4g") -> str:
    """A GitHub Markdown table (pandas' to_markdown needs tabulate; this does not); every
    cell through :func:`markdown_cell`, so each row has as many cells as the header."""
    def fmt(v: Any) -> str:
        if isinstance(v, (float, np.floating)):
            return "nan" if not np.isfinite(v) else format(float(v), floatfmt)
        return markdown_cell(v)

    cols = [markdown_cell(c) for c in table.columns]
    lines = ["| " + " | ".join(cols) + " |", "|" + "|".join("---" for _ in cols) + "|"]
    for row in table.itertuples(index=False):
        lines.append("| " + " | ".join(fmt(v) for v in row) + " |")
    return "\n".join(lines)
