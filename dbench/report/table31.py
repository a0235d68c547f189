"""results/table_3_1.md: Table 3.1 of the recurrent-denoising thesis laid out for a sequence sweep
(per method the mean SSIM over each scene's frames after the warm-up with its interval over
seeds, the median milliseconds per frame, how the method ran and the device), at every spp of
the sweep (:func:`table31_file`) or one (:func:`table31_md`, a section of results/README.md)."""
from __future__ import annotations

from pathlib import Path

import pandas as pd

from .. import io
from ..resolution import size_text
from . import tables, verdicts
from .cells import load_sweep, wall_text
from .formats import markdown_code, markdown_table


def table31_md(df, cells: list[dict], spp: int | None = None) -> list[str]:
    """Seed 001's Table 3.1 layout for a sequence sweep: per method, the mean SSIM over each
    scene's frames (after the warm-up, ± the interval over seeds) at ``spp`` (default the
    sweep's lowest), the median milliseconds per frame over the scenes, how the method ran
    (temporal, or a single-frame method frame by frame) and the device. A method whose SSIM
    equals the input's on every scene is marked so. Methods that did not run are left out."""
    if not len(df):
        return []
    spp = int(df.spp.min()) if spp is None else int(spp)
    d = df[df.spp == spp]
    scenes = sorted(d.scene.unique())
    modes = {str(c.get("method")): c.get("sequence_mode", "") for c in cells
             if c.get("status") == "ok" and c.get("spp") == spp}
    noisy = d[d.method == "noisy"].set_index("scene").ssim
    rows = []
    for method, g in d.groupby("method", sort=False):
        row = {"method": method}
        for scene in scenes:
            one = g[g.scene == scene]
            row[scene] = (verdicts.fmt_value(one.ssim.item(), one.ssim_ci.item(), ".3f")
                          if len(one) else "")
        row["ms per frame"] = f"{1e3 * float(g.time_s.median()):.2f}"
        extra = float(g.gradient_s.median()) if "gradient_s" in g else 0.0
        row["+ gradient samples, ms"] = f"{1e3 * extra:.1f}" if extra > 0 else ""
        same = method != "noisy" and len(noisy) and all(
            scene in noisy.index and one_ssim == noisy[scene]
            for scene, one_ssim in zip(g.scene, g.ssim))
        row["mode"] = "input" if method == "noisy" else (
            modes.get(method, "") + (" (returns the input)" if same else ""))
        row["device"] = "CPU"
        rows.append(row)
    order = sorted(rows, key=lambda r: -float(d[d.method == r["method"]].ssim.mean()))
    res = ", ".join(sorted({size_text(v) for v in d.res.dropna().unique()}))
    refs = ", ".join(sorted({f"{int(v)}" for v in d.ref_spp.dropna().unique()}))
    return [f"### Table 3.1 layout (seed 001): SSIM and time per frame at {spp} spp", "",
            f"SSIM against {refs}-spp references over the frames after the warm-up, "
            f"{res} px; ms per frame: median over the scenes of each cell's median per-frame "
            f"time on this machine's CPU (the seed ran A-SVGF and BMFR on a GPU at 1280×758); "
            f"\"+ gradient samples\": the median per-frame time of rendering the re-shaded "
            f"A-SVGF samples the method uses, on top of the denoiser's time. "
            f"A method that returns its input does so where its statistics carry no "
            f"information (one sample per pixel has no variance).",
            "", markdown_table(pd.DataFrame(order), name_headers=True), ""]


def table31_file(results: Path, sweep_dir: Path) -> Path:
    """``results/table_3_1.md``: the Table 3.1 layout at every spp of a sequence sweep."""
    info, cells, _ = load_sweep(sweep_dir)
    df = tables.cells_frame(cells)
    rel = Path(sweep_dir).relative_to(results).as_posix()
    parts = ["# Seed 001's Table 3.1, regenerated", "",
             f"From the sweep {markdown_code(rel)} "
             f"({wall_text(info, cells) or 'see its sweep.json'}). "
             "Scenes: dbench's camera paths (the seed used Sponza, DeleteMe and Dragon); "
             "single-frame methods run frame by frame beside the temporal ones.", ""]
    for spp in sorted(df.spp.unique()):
        parts += table31_md(df, cells, spp)
    out = results / "table_3_1.md"
    io.write_text(out, "\n".join(parts))
    return out
