"""Sample values that are NaN or ±Inf in the renderer (a texture with NaN pixels) are counted as
0 by dbench's sums where Mitsuba's own film holds NaN; a run used to score such a scene
without a word. Both render paths and the reference count them, the counts travel with the
cache entries, and a run states them as a warning (README.md, "How renders work"). Sequences
and transient videos counted them only in their statistics' diagnostics (and their references
held NaN, which failed every method): they now count them too, per frame and over all bins,
and a run states them once, as for an image. A sweep records them in its cells and says them."""
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


def _scene(folder, bad: bool, mixed: bool = False):
    """The plane's scene in ``folder``, its texture with NaN pixels in one channel where
    ``bad``, and where ``mixed`` also NaN in all three and +Inf and -Inf in one."""
    tex = np.full((8, 8, 3), 0.5, np.float32)
    if bad:
        tex[2:5, 2:5, 1] = np.nan
    if mixed:
        tex[5:7, 5:7, :] = np.nan
        tex[0:2, 6:8, 0] = np.inf
        tex[6:8, 0:2, 2] = -np.inf
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


def test_the_host_path_counts_them_as_its_statistics_do(renderer, tmp_path):
    """render_passes' host path counts them itself without statistics (nonfinite.zeroed over
    a batch whose sums are not finite) and takes PowerSums' count with them (its compiled pass
    over the float32 batch): the same samples at the same seed, so the same count, one per
    channel, NaN and ±Inf alike, whichever transform; and so does the kernel path."""
    from dbench.datasets import render
    from dbench.datasets.scenes import catalogue as scenes
    bad = scenes.get(str(_scene(tmp_path, True, mixed=True)))
    for kernel in (False, True):
        _, _, plain = render.render_passes(bad, 16, 8, seed=1, progress=False, kernel=kernel)
        for transform in ("identity", "box-cox", "yeo-johnson"):
            _, st, timing = render.render_passes(bad, 16, 8, seed=1, stats=(transform, 0.5),
                                                 progress=False, kernel=kernel)
            assert timing["nonfinite_samples"] == plain["nonfinite_samples"] \
                == st.diagnostics["n_nonfinite"] > 0, (kernel, transform)


def test_the_scalar_reference_counts_them_as_0_too(renderer, tmp_path, monkeypatch):
    """On scalar variants a reference chunk is one ``mi.render`` call, whose film holds NaN
    where a sample was: the chunk's NaN pixel values count as 0 and are counted, as in the
    sequence and transient references; the reference used to hold NaN there."""
    from dbench.datasets import render
    from dbench.datasets.scenes import catalogue as scenes
    bad = scenes.get(str(_scene(tmp_path, True)))
    monkeypatch.setattr(render, "_kernel_path", lambda: False)  # the scalar variants' path
    counts: dict = {}
    ref, ref_var, _ = render.render_reference(bad, 16, 32, progress=False, counts=counts)
    assert counts["nonfinite_samples"] > 0
    assert np.isfinite(ref).all() and np.isfinite(ref_var).all()


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


#: The same plane as a Python scene file of another kind (README.md, "Python scene files"); a
#: Python file names its texture by an absolute path.
PYTHON = '''
def build(mi, width, height):
    T = mi.ScalarTransform4f
    return {{"type": "scene",
            "sensor": {{"type": "perspective", "fov": 45,
                        "to_world": T().look_at(origin=[0, 0, 3], target=[0, 0, 0],
                                                up=[0, 1, 0])}},
            "plane": {{"type": "rectangle", "bsdf": {{"type": "diffuse", "reflectance": {{
                "type": "bitmap", "filename": "{tex}", "filter_type": "nearest"}}}}}},
            "lamp": {{"type": "sphere", "center": [1.0, 1.0, 1.5], "radius": 0.3,
                      "emitter": {{"type": "area", "radiance": {{"type": "rgb", "value": 6}}}}}}}}

def camera(i):
    return [0, 0, 3], [0, 0, 0]
'''
KINDS = {"sequence": 'kind = "sequence"\nframes = 2\n',
         "transient": 'kind = "transient"\nwindow_start = 2.0\nwindow_end = 12.0\nbins = 4\n'}


def _python_scene(folder, kind: str):
    _scene(folder, True)
    path = folder / f"{kind}.py"
    path.write_text(PYTHON.format(tex=(folder / "tex.exr").as_posix()) + KINDS[kind])
    return path


def test_sequences_and_videos_count_them_in_every_frame_and_bin(renderer, tmp_path):
    """A sequence's counts are its frames' sums; a video's cover all its bins, with either
    collector; the images stay finite (the reference included, which held NaN)."""
    from dbench import datasets
    seq = datasets.load(str(_python_scene(tmp_path, "sequence")), spp=2, res=16, ref_spp=16,
                        needs={"color", "reference"}, cache=datasets.Cache(tmp_path / "c"),
                        progress=False)
    for key in ("nonfinite_samples", "ref_nonfinite_samples"):
        per_frame = [f.meta[key] for f in seq]
        assert all(n > 0 for n in per_frame) and seq.meta[key] == sum(per_frame), key
    per_frame_noisy = [f.meta["nonfinite_samples"] for f in seq]
    assert all(np.isfinite(f.color).all() and np.isfinite(f.reference).all() for f in seq)
    assert "in the noisy image and" in seq.meta["nonfinite_warning"]
    # rendered again with statistics (which count the same samples), then read back
    for k in range(2):
        stats = datasets.load(str(tmp_path / "sequence.py"), spp=2, res=16, progress=False,
                              needs={"color", "stats"}, cache=datasets.Cache(tmp_path / "c"))
        assert [f.meta["nonfinite_samples"] for f in stats] == per_frame_noisy, k
        if k == 0:
            assert [f.stats.diagnostics["n_nonfinite"] for f in stats] == per_frame_noisy
    path = _python_scene(tmp_path, "transient")
    for collector in ("a", "b"):
        video = datasets.load(str(path), spp=2, res=16, ref_spp=16, collector=collector,
                              needs={"color", "reference"}, progress=False,
                              cache=datasets.Cache(tmp_path / "c"))
        assert video.meta["nonfinite_samples"] > 0 and video.meta["ref_nonfinite_samples"] > 0
        assert np.isfinite(video.color).all() and np.isfinite(video.reference).all()
        # (b)'s steady image, one render of all spp, held NaN (and so its energy fraction)
        assert np.isfinite(video.steady).all(), collector
        assert np.isfinite(video.meta["energy_fraction"]), collector
        assert "in the noisy image and" in video.meta["nonfinite_warning"], collector


def test_a_run_of_a_sequence_or_a_video_states_them_as_for_an_image(renderer, tmp_path,
                                                                    capsys):
    for kind in KINDS:
        path = _python_scene(tmp_path, kind)
        for k in range(2):  # rendered, then read back from the cache
            out = tmp_path / f"{kind}{k}"
            assert cli.main(["run", "--method", "noisy", "--scene", str(path), "--spp", "2",
                             "--res", "16", "--ref-spp", "16", "--repeats", "1", "--quiet",
                             "--cache", str(tmp_path / "cache"), "--out", str(out)]) == 0
            err = capsys.readouterr().err
            said = [line for line in err.splitlines() if "NaN or ±Inf sample values" in line]
            # once, for the whole sequence (its frames' sum), not once per frame
            assert len(said) == 1 and "in the noisy image and" in said[0], (kind, err)
            assert said[0].removeprefix("warning: ") in (out / "report.md").read_text()


def test_a_sweep_records_them_in_its_cells_and_says_them(renderer, tmp_path, capsys):
    """A sweep's cells record what their inputs say of themselves (``input_warnings``, as
    ``dbench run`` prints it), and its summary and README say it, once per scene (the spp named
    where it holds at some only); a sweep over such a scene used to give a clean-looking
    table."""
    import json
    import shutil

    image = _scene(tmp_path, True)
    (tmp_path / "seq").mkdir()
    sequence = _python_scene(tmp_path / "seq", "sequence")
    results = tmp_path / "results"
    assert cli.main(["sweep", "--methods", "noisy", "--scenes", f"{image},{sequence}",
                     "--spp", "2", "--res", "16", "--ref-spp", "16", "--repeats", "1",
                     "--quiet", "--cache", str(tmp_path / "cache"),
                     "--out", str(results / "sweep")]) == 0
    out = " ".join(capsys.readouterr().out.split())  # the summary's lines are wrapped
    shutil.copytree(results / "sweep", results / "sweep-beside")  # a sweep beside the main one
    assert cli.main(["report", "--results", str(results)]) == 0
    readme = (results / "README.md").read_text()
    assert "## Input warnings" in readme and "### Input warnings" in readme
    for name in ("scene.xml", "sequence.py"):
        cell = json.loads((results / "sweep" / "cells" / name / "00002spp" / "noisy.json")
                          .read_text())
        said = cell["input_warnings"]  # the sequence's once, summed over its frames
        assert len(said) == 1 and "NaN or ±Inf sample values" in said[0], name
        line = f"{name}: {said[0]}"  # the sweep's one spp: no spp to name
        assert f"warning: {line}" in out and f"- {line}\n" in readme, (name, out)


def _put_as_before_the_counts(monkeypatch):
    """``Cache.put`` as the code before the counts were kept wrote its entries: keys without
    the NONFINITE_VERSION marker, meta without ``nonfinite_samples``, and a reference holding
    NaN (as a sequence's or video's reference did where a sample was). Returns the undo."""
    from dbench.datasets.cache import Cache
    put = Cache.put

    def spoiled(buffers):
        out = dict(buffers or {})
        if "reference" in out:
            out["reference"] = out["reference"].copy()
            out["reference"].reshape(-1)[0] = np.nan
        return out

    def old_put(self, kind, description, images=None, arrays=None, meta=None, **kw):
        description = {k: v for k, v in description.items() if k != "nonfinite"}
        meta = {k: v for k, v in (meta or {}).items() if k != "nonfinite_samples"}
        return put(self, kind, description, spoiled(images), spoiled(arrays), meta, **kw)

    monkeypatch.setattr(Cache, "put", old_put)
    return lambda: monkeypatch.setattr(Cache, "put", put)


def test_entries_cached_before_the_counts_are_not_read_as_new(renderer, tmp_path, monkeypatch):
    """A noisy or reference entry written before the counts were kept (no count, for a
    sequence's or video's reference NaN pixels, which failed every method until the cache was
    cleared) is never served: each kind is rendered again (datasets.nonfinite.NONFINITE_VERSION
    in its key), and the new entries hold their counts, read back on the next load."""
    from dbench import datasets
    from dbench.data import Sequence
    image = _scene(tmp_path, True)
    sequence = _python_scene(tmp_path, "sequence")
    video = _python_scene(tmp_path, "transient")
    loads = {"image": dict(scene=str(image), spp=4, res=16, needs={"color", "stats",
                                                                   "reference"}),
             "sequence": dict(scene=str(sequence), spp=2, res=16,
                              needs={"color", "stats", "reference"}),
             "sequence, colour only": dict(scene=str(sequence), spp=2, res=16,
                                           needs={"color", "reference"}),
             "video (a)": dict(scene=str(video), spp=2, res=16, collector="a",
                               needs={"color", "stats", "reference"}),
             "video (b)": dict(scene=str(video), spp=2, res=16, collector="b",
                               needs={"color", "reference"})}
    for name, kw in loads.items():
        cache = datasets.Cache(tmp_path / "cache" / name.replace(" ", "_"))
        undo = _put_as_before_the_counts(monkeypatch)
        datasets.load(ref_spp=16, cache=cache, progress=False, **kw)
        undo()
        for k in range(2):  # rendered again over the old entries, then read back
            got = datasets.load(ref_spp=16, cache=cache, progress=False, **kw)
            metas = list(got) if isinstance(got, Sequence) else [got]
            # the colour, statistics and references (features and emitter buffers are shared)
            counted = ("color", "stats", "frame", "reference")
            hits = [h for h in got.meta["cache_hits"] if h.startswith(counted)]
            rendered = [h for h in got.meta["rendered"] if h.startswith(counted)]
            assert (rendered, hits)[k] and not (rendered, hits)[1 - k], (name, k, hits)
            for m in [got.meta] + [f.meta for f in metas if f is not got]:
                assert m["nonfinite_samples"] > 0 and m["ref_nonfinite_samples"] > 0, (name, k)
            for f in metas:
                assert np.isfinite(f.reference).all(), (name, k)


#: A room whose back wall's texture holds NaN texels, seen from the camera and lit by bounces:
#: a path that carries such a value reaches several bins of a fine window.
ROOM = '''
def build(mi, width, height):
    T = mi.ScalarTransform4f
    wall = {{"type": "diffuse", "reflectance": {{"type": "rgb", "value": 0.7}}}}
    return {{"type": "scene",
            "sensor": {{"type": "perspective", "fov": 60,
                        "to_world": T().look_at(origin=[0, 0, 3], target=[0, 0, 0],
                                                up=[0, 1, 0])}},
            "back": {{"type": "rectangle", "bsdf": {{"type": "diffuse", "reflectance": {{
                "type": "bitmap", "filename": "{tex}", "filter_type": "nearest"}}}}}},
            "floor": {{"type": "rectangle", "bsdf": wall,
                       "to_world": T().translate([0, -1, 1]).rotate([1, 0, 0], -90)}},
            "left": {{"type": "rectangle", "bsdf": wall,
                      "to_world": T().translate([-1, 0, 1]).rotate([0, 1, 0], 90)}},
            "lamp": {{"type": "sphere", "center": [0.0, 0.8, 1.0], "radius": 0.15,
                      "emitter": {{"type": "area", "radiance": {{"type": "rgb", "value": 20}}}}}}}}

kind = "transient"
window_start = {start}
window_end = {end}
bins = 40
max_depth = 5
'''


def test_a_videos_count_from_collector_a_says_how_it_was_made(renderer, tmp_path):
    """Collector (b) counts a NaN or ±Inf value once per bin a path reaches; collector (a)'s
    1-spp film drops such a value where it lands in an empty bin, so (a) counts them once per
    path in its steady image: fewer than (b) over a wide window (a path's values in several
    bins), more over a narrow one (values outside it). Same scene and seed; (a)'s warning says
    how its count was made, (b)'s does not (README.md, "How renders work")."""
    from dbench import datasets

    _scene(tmp_path, True)
    tex = (tmp_path / "tex.exr").as_posix()
    counts = {}
    for name, start, end in (("wide", 2.0, 14.0), ("narrow", 4.0, 4.6)):
        path = tmp_path / f"{name}.py"
        path.write_text(ROOM.format(tex=tex, start=start, end=end))
        for collector in ("a", "b"):
            video = datasets.load(str(path), spp=4, res=16, collector=collector,
                                  needs={"color"}, progress=False,
                                  cache=datasets.Cache(tmp_path / "c"))
            said = video.meta["nonfinite_warning"]
            per_path = "once per path over its whole length, not per bin" in said
            assert per_path == (collector == "a"), (name, collector, said)
            counts[name, collector] = video.meta["nonfinite_samples"]
    assert 0 < counts["wide", "a"] < counts["wide", "b"], counts
    assert counts["narrow", "a"] > counts["narrow", "b"] > 0, counts
