"""``dbench export`` refuses a scene that rendering would refuse before ``--out`` exists
(README.md, "Usage"): a plugin scene whose film filter is not a
box or whose film has another size, and a sequence's ``--frames`` beyond its frames, exit 2 in
one line and leave no folder, neither ``--out`` nor a parent it lacked (dbench/cli/commands.py
cmd_export)."""
from __future__ import annotations

import pytest

from dbench import cli
from plugin_scenes import PLUGIN  # tests/plugin_scenes.py

pytestmark = pytest.mark.mitsuba


@pytest.mark.parametrize("film, said", [
    # Mitsuba's Cornell box states a Gaussian filter
    ('d["sensor"]["film"].update(width=res.width, height=res.height)',
     "the film's reconstruction filter is gaussian;"),
    ('d["sensor"]["film"].update(width=16, height=16, rfilter={"type": "box"})',
     "build returned a 16×16 film for a 8×8 render;"),
])
def test_a_refused_plugin_scene_leaves_no_export_folder(isolated, renderer, tmp_path, capsys,
                                                        film, said):
    plugin = tmp_path / "room_plugin.py"
    plugin.write_text(PLUGIN.format(film=film))
    out, cache = tmp_path / "x" / "exp", tmp_path / "cache"
    rc = cli.main(["--plugin", str(plugin), "export", "my-room", "--out", str(out), "--spp", "4",
                   "--res", "8", "--ref-spp", "16", "--quiet", "--cache", str(cache)])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert err.startswith("dbench: scene my-room") and said in err, err
    assert not (tmp_path / "x").exists() and not list(cache.glob("*/*"))


def test_a_refused_frame_count_leaves_no_export_folder(renderer, tmp_path, capsys):
    out = tmp_path / "x" / "exp"
    rc = cli.main(["export", "flicker", "--out", str(out), "--spp", "4", "--res", "8",
                   "--ref-spp", "16", "--frames", "999", "--quiet",
                   "--cache", str(tmp_path / "cache")])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and err == ("dbench: frames: flicker has 48 frames; expected an "
                               "integer in [1, 48], got 999"), err
    assert not (tmp_path / "x").exists()


def test_an_export_folder_that_cannot_be_written_leaves_no_folders(tmp_path, monkeypatch,
                                                                  capsys):
    """The write check creates --out and its missing parents to probe them; refused, it
    removes them again (they were left behind, empty)."""
    import errno

    from dbench import io

    def denied(*_a, **_k):
        raise OSError(errno.EACCES, "Permission denied")

    monkeypatch.setattr(io.tempfile, "mkstemp", denied)
    out = tmp_path / "new" / "deeper" / "ex"
    rc = cli.main(["export", "cornell", "--spp", "2", "--res", "8", "--ref-spp", "16",
                   "--out", str(out), "--no-cache"])
    err = capsys.readouterr().err
    assert rc == 2 and "cannot write there (Permission denied)" in err, err
    assert not (tmp_path / "new").exists()
