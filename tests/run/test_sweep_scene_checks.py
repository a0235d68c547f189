"""A sweep refuses a scene its turn would refuse before it writes or renders anything (README.md,
"Usage"; the ``dbench sweep`` paragraph): a plugin scene whose
film filter is not a box or whose film has another size, and a folder of renders that does not
hold the sweep's reference spp, spp, size or seeds, leave no ``--out``, no ``sweep.json``
change and no cell of another scene (dbench/run/sweep_names.py check_scenes)."""
from __future__ import annotations

from pathlib import Path

import pytest

from dbench import cli
from cli_args import with_options  # tests/cli_args.py
from plugin_scenes import PLUGIN  # tests/plugin_scenes.py

pytestmark = pytest.mark.mitsuba


TINY = ["--methods", "noisy", "--spp", "4", "--res", "8", "--ref-spp", "16", "--repeats", "1",
        "--quiet"]


def _tree(root: Path) -> dict[str, bytes]:
    return {p.relative_to(root).as_posix(): p.read_bytes()
            for p in sorted(root.rglob("*")) if p.is_file()}


def _one_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    return err


@pytest.mark.parametrize("film, said", [
    # Mitsuba's Cornell box states a Gaussian filter
    ('d["sensor"]["film"].update(width=res.width, height=res.height)',
     "the film's reconstruction filter is gaussian;"),
    ('d["sensor"]["film"].update(width=16, height=16, rfilter={"type": "box"})',
     "build returned a 16×16 film for a 8×8 render;"),
])
def test_a_refused_plugin_scene_leaves_no_sweep_folder_and_no_history(isolated, renderer,
                                                                      tmp_path, capsys, film,
                                                                      said):
    plugin = tmp_path / "room_plugin.py"
    plugin.write_text(PLUGIN.format(film=film))
    out, cache = tmp_path / "x" / "sw", tmp_path / "cache"
    refused = ["--plugin", str(plugin), "sweep", "--scenes", "my-room", *TINY,
               "--cache", str(cache), "--out", str(out)]
    assert cli.main(refused) == 2
    err = _one_line(capsys)
    assert err.startswith("dbench: scene my-room") and said in err, err
    assert not (tmp_path / "x").exists() and not cache.exists()  # nor the probes' cache
    # into a sweep folder that holds a finished run: sweep.json gains no failed run, however
    # often the refused sweep is tried
    assert cli.main(["sweep", "--scenes", "cornell", *TINY, "--cache", str(cache),
                     "--out", str(out)]) == 0
    capsys.readouterr()
    before = _tree(out)
    for _ in range(2):
        assert cli.main(refused) == 2
        assert said in _one_line(capsys)
    assert _tree(out) == before


@pytest.fixture(scope="module")
def renders(renderer, tmp_path_factory) -> Path:
    """A folder of cornell's renders at 16×16, spp 4 and 16, reference 64 spp."""
    root = tmp_path_factory.mktemp("renders")
    assert cli.main(["export", "cornell", "--out", str(root / "exp"), "--spp", "4,16",
                     "--res", "16", "--ref-spp", "64", "--quiet",
                     "--cache", str(root / "cache")]) == 0
    return root / "exp"


@pytest.mark.parametrize("change, said", [
    (["--ref-spp", "32"], "--ref-spp: the reference in {where} has 64 spp; got 32"),
    (["--spp", "4,8"], "{where}: spp 8 is not offered; expected one of [4, 16]"),
    (["--res", "8"], "--res: {where} holds 16x16 images; got 8"),
    (["--seeds", "2"], "--seed/--seeds: {where} holds one noisy image per spp, made with one "
                       "seed; seed 1 was asked for (a folder offers --seed 0 and --seeds 1)"),
    (["--transform", "yeo-johnson"], "--transform: the statistics in {where} were gathered "
                                     "with box-cox (λ 0.5); yeo-johnson (λ 0.5) was asked for "
                                     "(give theirs, or leave --transform out)"),
])
def test_a_mixed_sweep_refuses_a_folders_settings_before_any_scene_renders(
        renders, tmp_path, capsys, change, said):
    settings = {"--spp": "4", "--res": "16", "--ref-spp": "64", "--seeds": "1"}
    settings.update(zip(change[::2], change[1::2]))
    out, cache = tmp_path / "x" / "sw", tmp_path / "cache"
    rc = cli.main(["sweep", "--scenes", f"cornell,{renders}", "--methods", "noisy",
                   "--repeats", "1", "--quiet", "--cache", str(cache), "--out", str(out),
                   *[x for kv in settings.items() for x in kv]])
    assert rc == 2
    assert _one_line(capsys) == "dbench: " + said.format(where=f"{renders}/cornell")
    # the scene before the folder (cornell) was neither rendered nor written
    assert not (tmp_path / "x").exists() and not cache.exists()


@pytest.mark.parametrize("scene, flag, said", [
    ("flicker", ["--frames", "999"], "dbench: --frames: expected an integer in [1, "),
    # its default bins, not asked for, are too many for the film at this size
    ("cornell-transient", ["--res", "2048"],
     "dbench: cornell-transient's bins: expected an integer in [1, "),
])
def test_a_sequence_or_transient_setting_is_refused_before_any_scene_renders(
        isolated, tmp_path, capsys, scene, flag, said):
    """Checked for every scene before the first renders: the sweep's cornell never renders."""
    cache = tmp_path / "cache"
    rc = cli.main(["sweep", "--scenes", f"cornell,{scene}", *with_options(TINY, *flag), "--cache",
                   str(cache), "--out", str(tmp_path / "x" / "sw")])
    assert rc == 2
    assert _one_line(capsys).startswith(said)
    assert not (tmp_path / "x").exists() and not cache.exists()


@pytest.mark.parametrize("scene, flag, field", [("orbit", ["--frames", "2"], "frames"),
                                                ("cornell-transient", ["--bins", "4"], "bins")])
def test_a_sweep_mixing_kinds_gives_frames_or_bins_to_the_scenes_that_take_them(
        renderer, tmp_path, capsys, scene, flag, field):
    """A sweep over cornell and orbit with --frames 2 wrote sweep.json and cornell's skipped
    cells, then ended with "frames: cornell is a steady scene" (exit 2) while prerendering,
    after any scene sorted before it had rendered; --frames is refused only where no scene
    reads it (tests/cli/test_cli_silent_inputs.py), so the sequence takes it and cornell
    renders as without it (its cells' identities record none)."""
    import json

    out = tmp_path / "sw"
    assert cli.main(["sweep", "--scenes", f"cornell,{scene}", *TINY, *flag, "--cache",
                     str(tmp_path / "cache"), "--out", str(out)]) == 0
    assert "0 errors" in capsys.readouterr().out
    cells = {p.parent.parent.name: json.loads(p.read_text())
             for p in out.glob("cells/*/*/noisy.json")}
    assert cells[scene]["status"] == cells["cornell"]["status"] == "ok"
    assert cells[scene]["identity"][field] == int(flag[1])
    assert cells["cornell"]["identity"][field] is None


def test_the_published_report_of_a_short_sequence_says_which_frames_it_averaged(renderer,
                                                                                 tmp_path):
    """A sweep of 2-frame sequences averages both frames (no more than the warm-up), while
    the results README said the means were over the frames after the 8-frame warm-up."""
    from dbench.report import publish

    results = tmp_path / "results"
    assert cli.main(["sweep", "--scenes", "orbit", *TINY, "--frames", "2", "--cache",
                     str(tmp_path / "cache"), "--out", str(results / "sweep")]) == 0
    cell = (results / "sweep" / "cells" / "orbit" / "00004spp" / "noisy.json").read_text()
    assert '"frames": 2' in cell and '"warmup": 8' in cell
    text = publish.build_readme(results, results / "sweep")
    assert "after the 8-frame warm-up (all of a sequence of 8 or fewer)." in text
