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


def markdown_table(table: pd.DataFrame, floatfmt: str = ".4g") -> str:
    """A GitHub Markdown table (pandas' to_markdown needs tabulate; this does not)."""
    def fmt(v: Any) -> str:
        if isinstance(v, (float, np.floating)):
            return "nan" if not np.isfinite(v) else format(float(v), floatfmt)
        return str(v)

    cols = [str(c) for c in table.columns]
    lines = ["| " + " | ".join(cols) + " |", "|" + "|".join("---" for _ in cols) + "|"]
    for row in table.itertuples(index=False):
        lines.append("| " + " | ".join(fmt(v) for v in row) + " |")
    return "\n".join(lines)
