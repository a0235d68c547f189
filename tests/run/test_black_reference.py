"""A scene whose reference is black everywhere is refused before any method runs: every method
would score 0 error on it and tie (dbench/run/inputs.py, check_reference_lit)."""
import numpy as np
import pytest

from dbench import cli
from dbench.data import Frame, Sequence, TransientFrame
from dbench.errors import DbenchInputError
from dbench.run.inputs import check_reference_lit

DARK = """<scene version="3.0.0">
  <sensor type="perspective"><float name="fov" value="40"/>
    <transform name="to_world"><lookat origin="0,0,4" target="0,0,0" up="0,1,0"/></transform>
    <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/>
    </film></sensor>
  <shape type="sphere"><bsdf type="diffuse"/></shape>
  <shape type="rectangle"><transform name="to_world"><translate z="2"/></transform>
    <emitter type="area"><rgb name="radiance" value="0"/></emitter></shape>
</scene>
"""


def test_a_scene_lit_by_a_zero_radiance_emitter_is_refused_in_one_line(tmp_path, capsys):
    scene = tmp_path / "dark.xml"
    scene.write_text(DARK)
    rc = cli.main(["run", "--method", "noisy,jbf", "--scene", str(scene), "--spp", "4",
                   "--res", "8", "--ref-spp", "16", "--cache", str(tmp_path / "cache"),
                   "--out", str(tmp_path / "out"), "--quiet"])
    err = capsys.readouterr().err
    assert rc == 2 and err.startswith("dbench: scene dark.xml: the reference is 0 in every "
                                      "pixel") and err.count("\n") == 1, (rc, err)
    assert not (tmp_path / "out").exists()  # no report of a 0-error tie


def _frame(value):
    ref = np.full((4, 4, 3), value, np.float32)
    return Frame(color=ref.copy(), reference=ref)


def test_a_frame_with_any_light_passes_and_a_black_one_is_refused():
    lit = _frame(0.0)
    lit.reference[2, 1, 0] = 1e-6
    check_reference_lit(lit, "s")
    with pytest.raises(DbenchInputError, match=r"^scene s: the reference is 0 in every pixel \("):
        check_reference_lit(_frame(0.0), "s")
    check_reference_lit(Frame(color=np.zeros((4, 4, 3), np.float32)), "s")  # no reference


def test_a_sequence_is_refused_only_when_every_frame_is_black():
    frames = [_frame(0.0) for _ in range(3)]
    with pytest.raises(DbenchInputError, match="every pixel and frame"):
        check_reference_lit(Sequence(frames), "s")
    frames[2].reference[0, 0, 1] = 0.5  # a light that comes on in the last frame
    check_reference_lit(Sequence(frames), "s")


def test_a_video_black_in_its_time_window_is_refused():
    ref = np.zeros((2, 3, 5, 3), np.float32)
    video = TransientFrame(color=ref.copy(), reference=ref)
    with pytest.raises(DbenchInputError, match="time bin .*within the video's time window"):
        check_reference_lit(video, "s")
    ref[1, 2, 4, 0] = 2.0
    check_reference_lit(TransientFrame(color=ref.copy(), reference=ref), "s")
