"""Plain table formats: pandas → CSV files (written atomically) and GitHub Markdown tables."""
from __future__ import annotations

import re
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
import pandas as pd

from .. import io


def counted(n: int, noun: str, plural: str | None = None) -> str:
    """``1 scene``, ``2 scenes``, ``0 errors``: a count with its noun, singular for one."""
    return f"{n} {noun if n == 1 else plural or noun + 's'}"


def cores_text(usable: Any, present: Any) -> str:
    """``2 cores``, or ``2 of 16 cores`` where a process may use fewer cores (``usable``: its
    affinity mask, cgroup quota) than the machine has (``present``); where one count is no
    integer (a record made before ``usable_cores`` was kept) the other alone. The one wording
    of a live process (:func:`dbench.run.machine.cores_text`, ``machine_label``, which a cell
    records and :mod:`dbench.report.cells` reads back) and of a run's recorded machine
    (:func:`dbench.report.run_report.machine_md`)."""
    def count(n: Any) -> bool:
        return isinstance(n, int) and not isinstance(n, bool)

    if count(usable) and count(present) and usable < present:
        return f"{usable} of {present} cores"
    n = present if count(present) else usable if count(usable) else None
    return f"{n} cores" if n is not None else "cores unknown"  # "1 cores": as recorded


def write_csv(path: str | Path, table: pd.DataFrame) -> None:
    with io.atomic_path(path, suffix=".tmp.csv") as tmp:
        table.to_csv(tmp, index=False, float_format="%.6g", encoding="utf-8")


#: What Markdown reads as markup wherever it stands in running text or a table cell:
#: emphasis and strikethrough (``*``, ``_``, ``~``), code spans, HTML tags and entities (``<``,
#: ``>``, ``&``), table cells (``|``) and the escape itself.
_MARKUP = re.compile(r"([\\`*_~<>&|])")
#: Brackets make a link or an image only as ``[text](url)``, ``[text][ref]`` or a reference
#: definition ``[ref]: url``, a checkbox only as ``[ ]`` at a list item's start, a heading
#: starts with ``#``: a ``]`` before ``(``, ``[`` or ``:`` is escaped, and a ``[`` or ``#``
#: that starts the text, so that a label such as ``jbf[radius=3]`` stays as it reads.
_BRACKETS = re.compile(r"\](?=[(\[:])|^[\[#]")
#: A ``|`` that no backslash escapes (an even number of backslashes before it, none included).
_BARE_PIPE = re.compile(r"(?<!\\)((?:\\\\)*)\|")
#: The columns :func:`markdown_table` treats as names (a plugin's method, a user's scene).
NAME_COLUMNS = ("method", "scene", "base_method")


def markdown_text(text: Any) -> str:
    """A method or scene name (a plugin may register any name, a scene file's name is its
    file's; README.md "Add your own denoiser") as literal Markdown text: every character
    Markdown reads as markup is escaped with a backslash, which GitHub shows as the character
    itself (``a_b_c``, ``<x>``, ``*star*`` read as written, not as emphasis or an HTML tag);
    a line break becomes a space. The one escape of names in report.md and README.md; CSV
    files keep names raw, the viewer escapes HTML (dbench/report/html.py)."""
    text = _MARKUP.sub(r"\\\1", " ".join(str(text).splitlines()))
    return _BRACKETS.sub(lambda m: "\\" + m.group(0), text)


def markdown_code(text: Any) -> str:
    """``text`` as a Markdown code span, fenced by more backticks than it holds in a row (a
    backtick in a name would otherwise end the span)."""
    text = " ".join(str(text).splitlines())
    run = max((len(m) for m in re.findall(r"`+", text)), default=0)
    fence = "`" * (run + 1)
    pad = " " if run or text.startswith(" ") else ""
    return f"{fence}{pad}{text}{pad}{fence}"


def markdown_cell(text: Any) -> str:
    """``text`` as one cell of a GitHub Markdown table: a ``|`` in a method or scene name (a
    plugin may register any name, README.md "Add your own denoiser") would end the cell and
    shift every number after it into the next column, so it is escaped (``\\|``, which GitHub
    shows as ``|``) unless a backslash already escapes it (:func:`markdown_text`); a line
    break would end the row, so it becomes a space."""
    return _BARE_PIPE.sub(r"\1\\|", " ".join(str(text).splitlines()))


def markdown_table(table: pd.DataFrame, floatfmt: str = ".4g",
                   names: Sequence[str] = NAME_COLUMNS, name_headers: bool = False) -> str:
    """A GitHub Markdown table (pandas' to_markdown needs tabulate; this does not); every
    cell through :func:`markdown_cell`, so each row has as many cells as the header; the cells
    of the ``names`` columns (and, with ``name_headers``, the headers: a table whose columns
    are scenes) are names, through :func:`markdown_text`."""
    def fmt(v: Any, name: bool = False) -> str:
        if isinstance(v, (float, np.floating)):
            return "nan" if not np.isfinite(v) else format(float(v), floatfmt)
        return markdown_text(v) if name else markdown_cell(v)

    head: Callable[[Any], str] = markdown_text if name_headers else markdown_cell
    cols = [head(c) for c in table.columns]
    is_name = [c in names for c in table.columns]
    lines = ["| " + " | ".join(cols) + " |", "|" + "|".join("---" for _ in cols) + "|"]
    for row in table.itertuples(index=False):
        lines.append("| " + " | ".join(fmt(v, n) for v, n in zip(row, is_name)) + " |")
    return "\n".join(lines)
