"""``dbench report`` over a sweep folder whose cells of one table were computed with different
settings or code (a ``--rerun`` over part of the grid recomputes only that part, README.md, the
``dbench sweep`` paragraph): the README and the results page say so, naming the label or scene,
the identity key and which cells hold which value; a folder without a mix says nothing."""
from __future__ import annotations

import copy
import json

from dbench.report import cells as cell_files, publish

MACHINE = {"cpu": "c", "cores": 2, "gpu": "none", "python": "3", "platform": "p",
           "packages": {}}
CONFIG = {"labels": ["noisy", "wt"], "methods": ["noisy", "wt"], "scenes": ["cornell"],
          "spp": [2, 4], "res": 16, "seeds": 2, "seed": 0, "ref_spp": 64, "repeats": 1}


def _cell(method: str, spp: int, **identity) -> dict:
    ident = {"scene": "cornell", "scene_fingerprint": "f00d", "kind": "steady", "res": 16,
             "spp": spp, "seeds": [0, 1], "ref_spp": 64, "ref_seed": 0, "transform": "box-cox",
             "lam": 0.5, "frames": None, "bins": None, "metrics": ["rmse"], "method": method,
             "params": {"weight": 1.0} if method == "wt" else {}, "method_version": "aaaa",
             "judge_version": "j1"}
    for k, v in identity.items():
        ident[k] = v
    c = {"status": "ok", "scene": "cornell", "method": method, "base_method": method,
         "spp": spp, "res": 16, "n_seeds": 2, "seeds": [0, 1], "ci_kind": "t 95 % over 2 seeds",
         "ref_spp": 64, "ref_rmse": 0.001, "time_s": 0.01, "n_nonfinite": 0, "params": {},
         "identity": ident}
    for m, v in (("rmse", 0.1), ("relmse", 0.02), ("rmse_surface", 0.05), ("ssim", 0.8),
                 ("flip", 0.2), ("relmse_surface", 0.02)):
        c[m], c[m + "_ci"] = v / spp, v / 100
    return c


def _publish(tmp_path, cells) -> tuple[str, str]:
    for name in ("sweep", "sweep-extra"):  # the main sweep and one beside it, same cells
        sweep = tmp_path / "results" / name
        sweep.mkdir(parents=True)
        (sweep / "sweep.json").write_text(json.dumps({"config": CONFIG, "machine": MACHINE}))
        for c in cells:
            p = sweep / "cells" / "cornell" / f"{c['spp']:05d}spp" / f"{c['method']}.json"
            p.parent.mkdir(parents=True, exist_ok=True)
            p.write_text(json.dumps(c))
    text = publish.publish(tmp_path / "results").read_text(encoding="utf-8")
    return text, (tmp_path / "results" / "index.html").read_text(encoding="utf-8")


def test_cells_of_one_label_or_scene_with_other_settings_are_named(tmp_path):
    cells = [_cell("noisy", 2), _cell("wt", 2), _cell("noisy", 4, judge_version="j2"),
             _cell("wt", 4, params={"weight": 0.5}, method_version="bbbb",
                   judge_version="j2")]
    text, page = _publish(tmp_path, cells)
    flat = " ".join(text.split())
    assert ('⚠ cells computed with different settings side by side (see "Mixed settings" '
            r"in README.md): `wt`: method\_version, params.weight; cornell: judge\_version"
            ) in flat
    section = text[text.index("## Mixed settings"):text.index("## Convergence")]
    assert '- `wt`: params.weight is 1.0 in cornell 2 spp; 0.5 in cornell 4 spp' in section
    assert (r'- `wt`: method\_version is "aaaa" in cornell 2 spp; "bbbb" in cornell 4 spp'
            in section)
    assert (r'- cornell: judge\_version is "j1" in 2 spp noisy, 2 spp wt; "j2" in 4 spp noisy, '
            '4 spp wt') in section
    assert "⚠ cells computed with different settings side by side" in page  # the results page
    extra = text[text.index("## Sweep `sweep-extra`"):]
    assert "Mixed settings (cells computed with different settings or code" in extra
    assert '- `wt`: params.weight is 1.0 in cornell 2 spp; 0.5 in cornell 4 spp' in extra


def test_a_sweep_without_a_mix_says_nothing(tmp_path):
    # the grid's own axes (spp, the reference's spp, the feature buffers' spp) are no mix
    cells = [_cell("noisy", 2), _cell("wt", 2), _cell("noisy", 4, ref_spp=128, feature_spp=4),
             _cell("wt", 4, ref_spp=128, feature_spp=4)]
    text, page = _publish(tmp_path, cells)
    assert "Mixed settings" not in text and "⚠ cells computed" not in page
    assert "## Sweep `sweep-extra`" in text
    assert cell_files.mixed_settings(cells) == []
    # a cell of the older format (no identity) is not compared
    old = copy.deepcopy(cells)
    del old[3]["identity"]
    old[1]["identity"]["params"] = {"weight": 2.0}
    assert cell_files.mixed_settings(old) == []


def test_the_sweep_warns_when_its_cells_stand_beside_cells_of_other_settings():
    """``dbench sweep --rerun --spp 4`` recomputes the 4-spp cells only: its closing lines
    (dbench/cli/commands.py, ``_sweep_summary``) compare them with the folder's 2-spp cells."""
    from dbench.report import terminal

    old = [_cell("noisy", 2), _cell("wt", 2)]
    new = [_cell("noisy", 4), _cell("wt", 4, params={"weight": 0.5})]
    text = " ".join(" ".join(terminal.sweep_summary(new, beside=old + new)).split())
    assert ("warning: cells computed with different settings side by side (dbench report lists "
            "them under \"Mixed settings\"): `wt`: params.weight") in text
    assert "warning: cells computed" not in " ".join(terminal.sweep_summary(new))


def test_names_in_mixed_settings_and_the_sweep_folder_are_literal_markdown(tmp_path):
    # a scene's name is its file's, a label any plugin's name, a folder any name: Markdown
    # reads none of them as markup (README.md "Add your own denoiser")
    scene, label = "a_b*c*", "w`t"

    def named(c: dict) -> dict:
        c = copy.deepcopy(c)
        c["scene"] = c["identity"]["scene"] = scene
        if c["method"] == "wt":
            c["method"] = c["base_method"] = label
        return c
    cells = [named(c) for c in (
        _cell("noisy", 2), _cell("wt", 2), _cell("noisy", 4, judge_version="j2"),
        _cell("wt", 4, params={"weight": "x_y_z"}, judge_version="j2"))]
    sweep = tmp_path / "results" / "sweep-a`b"
    sweep.mkdir(parents=True)
    config = {**CONFIG, "scenes": [scene], "labels": ["noisy", label], "methods": ["noisy", "wt"]}
    (sweep / "sweep.json").write_text(json.dumps({"config": config, "machine": MACHINE}))
    for i, c in enumerate(cells):
        p = sweep / "cells" / "s" / f"{c['spp']:05d}spp" / f"{i}.json"
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(json.dumps(c))
    text = publish.publish(tmp_path / "results", sweep).read_text(encoding="utf-8")
    section = text[text.index("## Mixed settings"):text.index("## Convergence")]
    assert r"- a\_b\*c\*: judge\_version is" in section
    assert r"in 2 spp noisy, 2 spp w\`t;" in section  # the cells, as literal text
    assert r'- `` w`t ``: params.weight is 1.0 in a\_b\*c\* 2 spp; "x\_y\_z" in' in section
    assert r"`` w`t ``: params.weight; a\_b\*c\*: judge\_version" in " ".join(text.split())
    assert "Sweep `` sweep-a`b ``: " in text
    page = (tmp_path / "results" / "index.html").read_text(encoding="utf-8")
    assert r"a\_b" not in page  # the results page escapes HTML, not Markdown


def test_a_mixed_key_is_literal_markdown_as_its_values_are(tmp_path):
    # a key names a method's parameter (params.<name>), which a plugin may call anything: as
    # written, `a_b*c` would start emphasis in the settings line and in "Mixed settings"
    cells = [_cell("noisy", 2), _cell("wt", 2, params={"a_b*c": 1.0}), _cell("noisy", 4),
             _cell("wt", 4, params={"a_b*c": 0.5})]
    text, page = _publish(tmp_path, cells)
    section = text[text.index("## Mixed settings"):text.index("## Convergence")]
    assert r"- `wt`: params.a\_b\*c is 1.0 in cornell 2 spp; 0.5 in cornell 4 spp" in section
    assert r'(see "Mixed settings" in README.md): `wt`: params.a\_b\*c.' in " ".join(
        text.split())
    extra = text[text.index("## Sweep `sweep-extra`"):]
    assert r"- `wt`: params.a\_b\*c is 1.0" in extra
    assert "params.a_b*c" not in text
    assert "`wt`: params.a_b*c" in page and r"a\_b" not in page  # the page escapes HTML
