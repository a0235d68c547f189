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


def _tree(root):
    return {p.relative_to(root).as_posix(): p.read_bytes()
            for p in sorted(root.rglob("*")) if p.is_file()} if root.exists() else None


SWEEP = ["--spp", "4", "--res", "8", "--ref-spp", "16", "--repeats", "1", "--quiet"]


@pytest.mark.mitsuba
@pytest.mark.parametrize("no_cache", [False, True])
def test_a_sweep_refuses_a_black_reference_before_it_writes_anything(renderer, tmp_path, capsys,
                                                                     no_cache):
    """The sweep wrote sweep.json (a run marked failed) and the skipped cells of its methods
    that do not apply before the reference was found black; a refused sweep now leaves no
    folder, and a sweep's folder as it was (dbench/run/sweep_names.py render_references)."""
    scene = tmp_path / "dark.xml"
    scene.write_text(DARK)
    cache = ["--no-cache"] if no_cache else ["--cache", str(tmp_path / "cache")]
    out = tmp_path / "x" / "sw"
    # accumulate does not apply to a steady scene: a skipped cell, planned before any render
    refused = ["sweep", "--methods", "noisy,accumulate", "--scenes", str(scene), *SWEEP, *cache,
               "--out", str(out)]
    assert cli.main(refused) == 2
    err = capsys.readouterr().err
    assert err.startswith("dbench: scene dark.xml: the reference is 0 in every pixel") \
        and err.count("\n") == 1, err
    assert not (tmp_path / "x").exists()
    assert cli.main(["sweep", "--methods", "noisy", "--scenes", "cornell", *SWEEP, *cache,
                     "--out", str(out)]) == 0
    capsys.readouterr()
    before = _tree(out)
    assert cli.main(refused[:4] + [f"cornell,{scene}"] + refused[5:]) == 2
    assert "dbench: scene dark.xml: the reference is 0" in capsys.readouterr().err
    assert _tree(out) == before  # no run in the history, no skipped cell of cornell's


@pytest.mark.mitsuba
def test_a_sweep_refuses_a_folder_whose_reference_is_black_before_it_writes(renderer, tmp_path,
                                                                            capsys):
    from exr_files import write_rgb  # tests/exr_files.py

    folder = tmp_path / "renders"
    assert cli.main(["export", "cornell", "--out", str(folder), "--spp", "4", "--res", "8",
                     "--ref-spp", "16", "--quiet", "--cache", str(tmp_path / "cache")]) == 0
    write_rgb(folder / "cornell_ref.hdr.exr", np.zeros((8, 8, 3), np.float32))
    capsys.readouterr()
    out = tmp_path / "x" / "sw"
    assert cli.main(["sweep", "--methods", "noisy", "--scenes", str(folder), "--spp", "4",
                     "--repeats", "1", "--quiet", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("dbench: scene cornell: the reference is 0 in every pixel") \
        and err.count("\n") == 1, err
    assert not (tmp_path / "x").exists()
