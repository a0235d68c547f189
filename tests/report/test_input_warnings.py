"""What a sweep's inputs say of themselves (each cell's ``input_warnings``: NaN or ±Inf samples
counted as 0, a folder's doubtful reference or normals; README.md, "How renders work") in the
reports of ``dbench report``: its README ("Input warnings") and its results page
(``results/index.html``), each distinct warning once per scene, with the spp where it holds
at some of them only."""
from __future__ import annotations

import json

from dbench.report import publish
from sweep_cells import ok_cell  # tests/sweep_cells.py

SPP = [4, 16, 64]
#: a folder's warning quotes its files' names, which may hold anything HTML reads as markup
EVERYWHERE = "the reference <ref>.exr & its normals_x are doubtful"
SOME = "the reference has 16 spp, no more than the noisy input's"


def _cells(scene: str = "cornell") -> list[dict]:
    cells = []
    for spp in SPP:
        for method in ("noisy", "jbf"):
            c = ok_cell(scene, spp, method)
            c["input_warnings"] = [EVERYWHERE] + ([SOME] if spp <= 16 else [])
            cells.append(c)
    return cells


def _publish(tmp_path, cells) -> tuple[str, str]:
    """(README.md, index.html) of ``dbench report`` over a main sweep and one beside it, both
    holding ``cells``."""
    results = tmp_path / "results"
    for name in ("sweep", "sweep-beside"):
        sweep = results / name
        sweep.mkdir(parents=True)
        (sweep / "sweep.json").write_text(json.dumps({"config": {
            "labels": ["noisy", "jbf"], "methods": ["noisy", "jbf"],
            "scenes": sorted({c["scene"] for c in cells}), "spp": SPP, "res": 16, "seeds": 1,
            "seed": 0, "repeats": 1}}))
        for c in cells:
            p = sweep / "cells" / c["scene"] / f"{c['spp']:05d}spp" / f"{c['method']}.json"
            p.parent.mkdir(parents=True, exist_ok=True)
            p.write_text(json.dumps(c))
    readme = publish.publish(results).read_text(encoding="utf-8")
    return readme, (results / "index.html").read_text(encoding="utf-8")


def test_the_readme_states_each_warning_once_per_scene(tmp_path):
    readme, _ = _publish(tmp_path, _cells())
    for title, end in (("## Input warnings", "## Convergence"),
                       ("### Input warnings", "### Headline")):
        section = readme[readme.index(title):]
        section = section[:section.index(end)]
        lines = [ln for ln in section.splitlines() if ln.startswith("- ")]
        # six cells carry the first, four the second: one line each, the spp named where
        # the warning does not hold at every spp of the scene
        assert lines == [r"- cornell: the reference \<ref\>.exr \& its normals\_x are doubtful",
                         "- cornell at 4, 16 spp: the reference has 16 spp, no more than the "
                         "noisy input's"], (title, section)


def test_the_results_page_states_them_beside_the_sweeps_settings(tmp_path):
    _, page = _publish(tmp_path, _cells("a<b>"))
    escaped = ("<li>a&lt;b&gt;: the reference &lt;ref&gt;.exr &amp; its normals_x are "
               "doubtful</li>")
    some = "<li>a&lt;b&gt; at 4, 16 spp: the reference has 16 spp, no more than the noisy "
    assert "<ref>" not in page and "a<b>" not in page
    for k, name in enumerate(("sweep", "sweep-beside")):
        section = page[page.index(f"<h2>Sweep {name}</h2>"):page.index(f'data-table="{k}"')]
        # under the sweep's settings line, above its grid
        assert section.index("Sweep `") < section.index("<h3>Input warnings</h3>"), section
        assert section.count("<li>") == 2 and escaped in section and some in section, section
        assert "as <code>dbench run</code> prints it" in section


def test_a_sweep_whose_inputs_said_nothing_has_no_such_section(tmp_path):
    cells = _cells()
    for c in cells:
        del c["input_warnings"]
    readme, page = _publish(tmp_path, cells)
    assert "Input warnings" not in readme and "Input warnings" not in page


def _nan(noisy: int, reference: int) -> str:
    from dbench.datasets.nonfinite import nonfinite_text

    return nonfinite_text(noisy, reference)


def test_warnings_that_differ_only_in_their_counts_are_one_line():
    from dbench.report.cells import input_warnings

    # each spp's render has its own NaN count; the reference (one render) the same count
    counts = {4: 12, 16: 48, 64: 190}
    cells = [dict(ok_cell("cornell", spp, m), input_warnings=[_nan(n, 3)])
             for spp, n in counts.items() for m in ("noisy", "jbf")]
    said = input_warnings(cells)
    assert said == ["cornell at 4, 16, 64 spp, respectively: " + _nan(1, 3).replace(
        "(1 in the noisy image", "(12, 48, 190 in the noisy image")], said


def test_counts_are_not_joined_where_the_spp_would_not_say_whose_they_are():
    from dbench.report.cells import input_warnings

    # two counts at one spp (two labels disagree): each text keeps its own line
    cells = [dict(ok_cell("cornell", 4, "noisy"), input_warnings=[_nan(12, 3)]),
             dict(ok_cell("cornell", 4, "jbf"), input_warnings=[_nan(13, 3)]),
             dict(ok_cell("cornell", 16, "noisy"), input_warnings=[_nan(48, 3)])]
    assert input_warnings(cells) == ["cornell at 4 spp: " + _nan(12, 3),
                                     "cornell at 4 spp: " + _nan(13, 3),
                                     "cornell at 16 spp: " + _nan(48, 3)]
    # the same text at every spp, and texts of other forms, are as before
    cells = [dict(ok_cell("cornell", spp, "noisy"), input_warnings=[_nan(5, 0), SOME])
             for spp in (4, 16)]
    assert input_warnings(cells) == sorted(["cornell: " + _nan(5, 0), "cornell: " + SOME])
