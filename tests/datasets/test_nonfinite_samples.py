"""Sample values that are NaN or ±Inf in the renderer (a texture with NaN pixels) are counted as
0 by dbench's sums where Mitsuba's own film holds NaN; a run used to score such a scene
without a word. Both render paths and the reference count them, the counts travel with the
cache entries, and a run states them as a warning (README.md, "How renders work")."""
import numpy as np

from dbench import cli
from exr_files import write_rgb  # tests/exr_files.py

SCENE = """<scene version="3.0.0">
  <integrator type="path"><integer name="max_depth" value="4"/></integrator>
  <sensor type="perspective"><float name="fov" value="45"/>
    <transform name="to_world"><lookat origin="0,0,3" target="0,0,0" up="0,1,0"/></transform>
    <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/>
      <rfilter type="box"/></film></sensor>
  <shape type="rectangle"><bsdf type="diffuse"><texture type="bitmap" name="reflectance">
    <string name="filename" value="tex.exr"/><string name="filter_type" value="nearest"/>
  </texture></bsdf></shape>
  <emitter type="constant"><rgb name="radiance" value="1"/></emitter>
</scene>"""


def _scene(folder, bad: bool):
    tex = np.full((8, 8, 3), 0.5, np.float32)
    if bad:
        tex[2:5, 2:5, 1] = np.nan
    write_rgb(folder / "tex.exr", tex)
    (folder / "scene.xml").write_text(SCENE)
    return folder / "scene.xml"


def test_both_render_paths_and_the_reference_count_non_finite_samples(renderer, tmp_path):
    from dbench.datasets import render
    from dbench.datasets.scenes import catalogue as scenes
    bad = scenes.get(str(_scene(tmp_path, True)))
    for kernel in (True, False):
        color, _, timing = render.render_passes(bad, 16, 4, progress=False, kernel=kernel)
        assert timing["nonfinite_samples"] > 0 and np.isfinite(color).all(), kernel
        _, st, timing = render.render_passes(bad, 16, 4, stats=("identity", 0.5),
                                             progress=False, kernel=kernel)
        # the statistics count the very same samples
        assert timing["nonfinite_samples"] == st.diagnostics["n_nonfinite"] > 0, kernel
    counts: dict = {}
    render.render_reference(bad, 16, 32, progress=False, counts=counts)
    assert counts["nonfinite_samples"] > 0
    (tmp_path / "clean").mkdir()
    clean = scenes.get(str(_scene(tmp_path / "clean", False)))
    assert render.render_passes(clean, 16, 4, progress=False)[2]["nonfinite_samples"] == 0


def test_a_run_states_them_also_from_the_cache(renderer, tmp_path, capsys):
    path = _scene(tmp_path, True)
    for k in range(2):  # rendered, then read back from the cache
        out = tmp_path / f"out{k}"
        assert cli.main(["run", "--method", "noisy", "--scene", str(path), "--spp", "4",
                         "--ref-spp", "16", "--repeats", "1", "--quiet", "--cache",
                         str(tmp_path / "cache"), "--out", str(out)]) == 0
        err = capsys.readouterr().err
        said = [line for line in err.splitlines() if "NaN or ±Inf sample values" in line]
        assert len(said) == 1 and "in the noisy image and" in said[0], err
        assert "NaN or ±Inf sample values" in (out / "report.md").read_text()
