"""An input with nothing to denoise is said: a scene whose every pixel sees one radiance (here
only a constant environment) gives a noisy image equal to its reference, every method scores
0 or ties, and the ranking carries no information (dbench/run/inputs.py, note_noise_free;
README.md, "How renders work")."""
import json

import numpy as np
import pytest

from dbench import cli
from dbench.data import Frame, SampleStats, Sequence, TransientFrame
from dbench.report.cells import load_cells
from dbench.report.html import input_warnings_html
from dbench.report.publish import input_warnings_md
from dbench.run.inputs import input_warnings, noise_free, note_noise_free

ENV = """<scene version="3.0.0">
  <sensor type="perspective"><float name="fov" value="40"/>
    <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/>
    </film></sensor>
  <emitter type="constant"><rgb name="radiance" value="0.3, 0.5, 0.7"/></emitter>
</scene>
"""
SAID = "the noisy image has no sample variance"
RUN = ["--spp", "4", "--res", "8", "--ref-spp", "16", "--quiet"]


def _frame(value=0.25, **kw):
    ref = np.full((4, 4, 3), value, np.float32)
    return Frame(color=ref.copy(), reference=ref, reference_var=np.zeros_like(ref), **kw)


def test_only_an_input_noise_free_at_every_pixel_is_flagged():
    assert noise_free(_frame())
    noisy = _frame()
    noisy.color[3, 2, 1] += 1e-6  # one pixel of noise: the ranking means something
    assert not noise_free(noisy)
    spread = _frame()
    spread.reference_var[0, 0, 0] = 1e-9  # the reference's chunks disagree at one pixel
    assert not noise_free(spread)
    shape = (4, 4, 3)
    stats = SampleStats(n=np.full(shape, 4.0), mean=np.zeros(shape), var_mean=np.zeros(shape),
                        m3=np.zeros(shape), transform="identity", lam=0.5)
    assert noise_free(_frame(stats=stats))
    stats.var_mean[1, 1, 2] = 1e-12  # the noisy samples themselves vary at one pixel
    assert not noise_free(_frame(stats=stats))
    assert not noise_free(Frame(color=np.zeros(shape, np.float32)))  # no reference: unknown
    folder = _frame()
    folder.meta["source"] = "folder"  # a folder's equal reference is its own warning
    assert not noise_free(folder)


def test_a_sequence_or_video_is_flagged_only_when_all_of_it_is_noise_free():
    frames = [_frame() for _ in range(3)]
    assert noise_free(Sequence(frames))
    frames[1].color[0, 0, 0] = 0.5
    assert not noise_free(Sequence(frames))
    ref = np.full((2, 3, 5, 3), 0.5, np.float32)
    video = TransientFrame(color=ref.copy(), reference=ref, total_var=np.zeros((2, 3, 3)))
    assert noise_free(video)
    note_noise_free([video])
    assert input_warnings(video) == [video.meta["noise_free_warning"]]
    assert "every pixel and time bin" in video.meta["noise_free_warning"]
    video.total_var[1, 2, 0] = 0.1
    assert not noise_free(video)


def test_every_seed_must_be_noise_free():
    seeds = [_frame(), _frame()]
    seeds[1].color[0, 0, 0] = 0.0
    note_noise_free(seeds)
    assert not any("noise_free_warning" in f.meta for f in seeds)


@pytest.mark.mitsuba
def test_a_constant_environment_is_said_by_run_and_recorded_by_a_sweep(renderer, tmp_path,
                                                                       capsys):
    scene = tmp_path / "env.xml"
    scene.write_text(ENV)
    cache = ["--cache", str(tmp_path / "cache")]
    assert cli.main(["run", "--method", "noisy", "--scene", str(scene), *RUN, *cache,
                     "--out", str(tmp_path / "run")]) == 0
    err = capsys.readouterr().err
    assert f"warning: {SAID} (it equals its expected value" in err, err
    assert err.count(SAID) == 1
    assert SAID in (tmp_path / "run" / "report.md").read_text(encoding="utf-8")
    out = tmp_path / "sweep"
    assert cli.main(["sweep", "--methods", "noisy", "--scenes", str(scene), *RUN, *cache,
                     "--repeats", "1", "--out", str(out)]) == 0
    cell = json.loads(next(out.glob("cells/*/*/noisy.json")).read_text(encoding="utf-8"))
    assert len(cell["input_warnings"]) == 1 and cell["input_warnings"][0].startswith(SAID)
    assert SAID in capsys.readouterr().out  # the sweep's summary
    cells = load_cells(out)  # the published README's and the results page's sections
    assert SAID in "\n".join(input_warnings_md(cells, "## Input warnings"))
    assert SAID in "\n".join(input_warnings_html(cells))


@pytest.mark.mitsuba
def test_a_scene_with_noise_says_nothing_of_it(renderer, tmp_path, capsys):
    assert cli.main(["run", "--method", "noisy", "--scene", "cornell", *RUN, "--cache",
                     str(tmp_path / "cache"), "--out", str(tmp_path / "run")]) == 0
    assert SAID not in capsys.readouterr().err
    assert SAID not in (tmp_path / "run" / "report.md").read_text(encoding="utf-8")


SKY_SEQUENCE = '''kind = "sequence"
frames = 2
def camera(i):
    return ([0, 0, 4 + 0.1 * i], [0, 0, 0])
def build(mi, width, height):
    return {"type": "scene", "sensor": {"type": "perspective", "fov": 45},
            "sky": {"type": "constant", "radiance": {"type": "rgb", "value": [0.3, 0.3, 0.3]}}}
'''
#: a uniform emitting wall filling a narrow view: every path has one length (one time bin)
WALL_VIDEO = '''kind = "transient"
window_start = 3.0
window_end = 6.0
bins = 20
def build(mi, width, height):
    T = mi.ScalarTransform4f
    return {"type": "scene", "sensor": {"type": "perspective", "fov": 10,
            "to_world": T().look_at(origin=[0, 0, 4], target=[0, 0, 0], up=[0, 1, 0])},
            "wall": {"type": "rectangle", "to_world": T().scale(10),
                     "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [1, 1, 1]}}}}
'''


@pytest.mark.mitsuba
@pytest.mark.parametrize("text, where", [(SKY_SEQUENCE, "at every pixel in every frame"),
                                         (WALL_VIDEO, "at every pixel and time bin")])
def test_a_noise_free_sequence_or_video_is_said_by_run(tr, tmp_path, capsys, text, where):
    scene = tmp_path / "scene.py"
    scene.write_text(text)
    assert cli.main(["run", "--method", "noisy", "--scene", str(scene), "--spp", "2", "--res",
                     "4", "--ref-spp", "16", "--quiet", "--cache", str(tmp_path / "cache"),
                     "--out", str(tmp_path / "run")]) == 0
    err = capsys.readouterr().err
    assert f"warning: {SAID} (it equals its expected value, the reference, {where})" in err, err
