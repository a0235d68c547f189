"""Options that used to be read as "not given" or ignored are refused with one line and exit 2,
before anything renders or is written (README.md, "Usage")."""
from pathlib import Path

import pytest
from cli_args import lamp_scene, refused, with_options  # tests/cli_args.py

from dbench import cli


def _run(tmp_path, *extra, scene="cornell"):
    return ["run", "--scene", scene, "--spp", "4", "--res", "8", "--ref-spp", "16",
            "--cache", str(tmp_path / "cache"), "--out", str(tmp_path / "out"), "--quiet",
            *extra]


@pytest.mark.parametrize("argv, option", [
    (["--method", ""], "--method"),              # used to run the noisy input alone, exit 0
    (["--method", ","], "--method"),
    (["--method", "noisy", "--out", ""], "--out"),  # used to write into results/runs/
    (["--method", "noisy", "--cache", " "], "--cache"),
])
def test_an_empty_value_is_refused_not_read_as_the_default(tmp_path, capsys, argv, option):
    base = [a for a in _run(tmp_path) if a not in ("--out", str(tmp_path / "out"))
            ] if "--out" in argv else _run(tmp_path)
    if "--cache" in argv:
        base = [a for a in base if a not in ("--cache", str(tmp_path / "cache"))]
    refused(capsys, base + argv, f"{option}: empty")
    assert not (tmp_path / "cache").exists() and not (tmp_path / "out").exists()


def test_empty_values_of_the_other_commands(tmp_path, capsys):
    refused(capsys, ["sweep", "--scenes", "", "--out", str(tmp_path / "sw")], "--scenes: empty")
    refused(capsys, ["export", "cornell", "--spp", "", "--out", str(tmp_path / "ex")],
            "--spp: empty")
    refused(capsys, ["export", "", "--out", str(tmp_path / "ex")], "scene: empty")
    refused(capsys, ["render", "--scene", ","], "--scene: empty")
    assert not (tmp_path / "sw").exists() and not (tmp_path / "ex").exists()


def test_frames_and_bins_are_refused_where_nothing_reads_them(tmp_path, capsys):
    refused(capsys, _run(tmp_path, "--method", "noisy", "--frames", "3"),
            "--frames: only sequence scenes", "cornell is a steady scene")
    refused(capsys, _run(tmp_path, "--method", "noisy", "--bins", "8"),
            "--bins: only transient scenes")
    refused(capsys, ["export", "cornell", "--frames", "2", "--out", str(tmp_path / "ex")],
            "--frames: only sequence scenes")
    assert not (tmp_path / "out").exists() and not (tmp_path / "ex").exists()


def test_a_scene_parameter_that_is_not_a_finite_number_is_refused(tmp_path, capsys):
    scene = tmp_path / "lamp.xml"
    scene.write_text(lamp_scene("8"))
    for value in ("nan", "1e400", "1,inf,1"):
        # Mitsuba takes them: a light of NaN radiance renders black, which every method
        # then matches perfectly
        refused(capsys, _run(tmp_path, "--method", "noisy", "--scene-param",
                             f"light={value}", scene=str(scene)), "not a finite number")
    assert not (tmp_path / "out").exists()


def test_bench_checks_its_output_and_sizes_before_timing(tmp_path, capsys):
    afile = tmp_path / "afile"
    afile.write_text("")
    refused(capsys, ["bench", "jbf", "--out", str(tmp_path)], "is a folder")
    refused(capsys, ["bench", "jbf", "--out", str(afile / "x.jsonl")], "not a folder")
    refused(capsys, ["bench", "jbf", "--width", "-5"], "--width/--height", "-5x720")
    refused(capsys, ["bench", "jbf", "--height", "0"], "--width/--height")
    refused(capsys, ["bench", "jbf", "--scene", "caustic"], "--scene: only bench render")


def test_render_refuses_a_cache_that_is_a_file(tmp_path, capsys):
    afile = tmp_path / "afile"
    afile.write_text("")
    refused(capsys, ["render", "--scene", "cornell", "--res", "8", "--cache", str(afile)],
            "--cache", "not a folder")
    assert Path(afile).read_text() == ""


def test_export_adds_only_to_its_own_folder(renderer, tmp_path, capsys):
    out = tmp_path / "exp"
    argv = ["export", "cornell", "--out", str(out), "--res", "8", "--ref-spp", "16", "--quiet",
            "--cache", str(tmp_path / "cache")]
    assert cli.main(argv + ["--spp", "4"]) == 0
    assert cli.main(argv + ["--spp", "16"]) == 0  # the same scene and reference: more spp
    assert (out / "cornell_0016.hdr.exr").is_file()
    # dataset.json (one per folder) would be rewritten for another scene or reference
    refused(capsys, ["export", "caustic", "--out", str(out), "--spp", "4", "--res", "8",
                     "--ref-spp", "16", "--quiet"], "holds an export with scene 'cornell'")
    refused(capsys, with_options(argv[:-2], "--spp", "4", "--ref-spp", "32"), "ref_spp 16")
    other = tmp_path / "mine"
    other.mkdir()
    (other / "notes.txt").write_text("someone's folder")
    refused(capsys, ["export", "cornell", "--out", str(other), "--spp", "4", "--res", "8"],
            "no export's dataset.json")
    assert sorted(p.name for p in other.iterdir()) == ["notes.txt"]


def test_a_sweep_does_not_start_in_a_folder_of_other_files(tmp_path, capsys):
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "thesis.tex").write_text("someone's work")
    refused(capsys, ["sweep", "--methods", "noisy", "--scenes", "cornell", "--spp", "4",
                     "--res", "8", "--ref-spp", "16", "--repeats", "1", "--out", str(mine),
                     "--cache", str(tmp_path / "cache")], "holds other files (thesis.tex)")
    assert sorted(p.name for p in mine.iterdir()) == ["thesis.tex"]


@pytest.mark.parametrize("argv, words", [
    (["sweep", "--methods", "jbf", "--scenes", "cornell", "--spp", "4,,16"], ("--spp", "empty item")),
    (["sweep", "--methods", "jbf,", "--scenes", "cornell"], ("--methods", "empty item")),
    (["sweep", "--methods", "jbf", "--scenes", "cornell,,flicker"], ("--scenes", "empty item")),
    (["export", "cornell", "--spp", "4,16,"], ("--spp", "empty item")),
    (["run", "--method", "all,jbf", "--scene", "cornell"], ("--method", "stands alone")),
    (["sweep", "--methods", "jbf,all", "--scenes", "cornell"], ("--methods", "stands alone")),
    (["stress", "--methods", "jbf,,nca"], ("--methods", "empty item")),
])
def test_comma_lists_with_empty_items_or_all_inside_are_refused(tmp_path, capsys, argv, words):
    # "4,,16" used to sweep 4 and 16 as if that were meant; "all,jbf" named no method "all"
    refused(capsys, [*argv, "--out", str(tmp_path / "out")], *words)
    assert not (tmp_path / "out").exists()


def test_one_parameter_given_two_values_is_refused(tmp_path, capsys):
    # the later one used to win silently
    refused(capsys, _run(tmp_path, "--method", "jbf", "--param", "radius=3",
                         "--param", "radius=5"), "--param radius=5", "radius=3", "one value")
    refused(capsys, _run(tmp_path, "--method", "jbf", "--param", "jbf.radius=3",
                         "--param", "jbf.radius=5"), "jbf.radius=3")
    assert not (tmp_path / "out").exists()


def test_a_method_parameter_wins_over_a_general_one_in_either_order():
    from dbench.cli.args import parse_params

    for items in (["radius=3", "jbf.radius=5"], ["jbf.radius=5", "radius=3"]):
        got = parse_params(items, ["noisy", "jbf", "svgf"])
        assert got["jbf"]["radius"] == 5, items
        assert got["noisy"] == {}
    # the same value twice is no conflict
    assert parse_params(["radius=3", "radius=3"], ["jbf"])["jbf"]["radius"] == 3


def test_a_sweep_refuses_frames_or_bins_that_none_of_its_scenes_reads(tmp_path, capsys):
    refused(capsys, ["sweep", "--methods", "jbf", "--scenes", "cornell,textured", "--frames",
                     "4", "--out", str(tmp_path / "sw")], "--frames: only sequence scenes",
            "cornell, textured")
    refused(capsys, ["sweep", "--methods", "jbf", "--scenes", "orbit", "--bins", "8",
                     "--out", str(tmp_path / "sw")], "--bins: only transient scenes")
    assert not (tmp_path / "sw").exists()


def test_a_lam_that_no_scene_reads_is_refused(tmp_path, capsys):
    """λ is read by box-cox and yeo-johnson alone: with the identity transform (asked for, or
    a transient scene's default) it changed nothing while the run recorded it."""
    refused(capsys, _run(tmp_path, "--method", "noisy", "--transform", "identity", "--lam",
                         "0.3"), "--lam: the identity transform takes no λ")
    refused(capsys, _run(tmp_path, "--method", "noisy", "--lam", "0.3",
                         scene="cornell-transient"), "--lam: only the box-cox and yeo-johnson",
            "cornell-transient (identity)")
    refused(capsys, ["sweep", "--methods", "jbf", "--scenes", "cornell-transient,fog-transient",
                     "--lam", "0.3", "--out", str(tmp_path / "sw")],
            "cornell-transient (identity), fog-transient (identity)")
    assert not (tmp_path / "out").exists() and not (tmp_path / "sw").exists()


def test_lam_is_taken_where_one_of_the_scenes_reads_it():
    import argparse

    from dbench.cli.args import DEFAULT_LAM, check_lam
    from dbench.datasets.scenes import catalogue

    names = ["cornell-transient", "cornell"]
    scenes = [catalogue.get(n) for n in names]
    args = argparse.Namespace(lam=0.3, transform=None)
    check_lam(args, scenes, names, [4])
    assert args.lam == 0.3
    args = argparse.Namespace(lam=None, transform="identity")
    check_lam(args, scenes[:1], names[:1], [4])  # not given: the default, read or not
    assert args.lam == DEFAULT_LAM


@pytest.mark.parametrize("method, param, said", [
    # a string from the command line used to read as true: oidn ran with clean_aux on,
    # labelled oidn[clean_aux=false]
    ("oidn", "clean_aux=false", "clean_aux: expected True or False, got 'false'"),
    ("oidn", "clean_aux=2", "clean_aux: expected True or False, got 2"),
    ("jbf", "radius=2.5", "radius: expected an integer, got 2.5"),   # used to truncate
    ("jbf", "sigma_depth=nan", "sigma_depth: expected a number, got 'nan'"),
    # these were refused only on the first frame, after rendering, with exit 4
    ("nca", "iterations=-1", "iterations: expected an integer >= 0, got -1"),
    ("nca", "spp=0", "spp: expected a sample count >= 1, got 0"),
    ("nca", "spp=0.5", "spp: expected a sample count >= 1, got 0.5"),
    ("autoencoder", "threads=-1", "threads: expected an integer >= 1"),  # used to run
    ("autoencoder", "spp=-1", "spp: expected a sample count >= 1, got -1"),
    ("jbf", "features=1", "features: expected a name or a sequence of names"),  # exit 1
])
def test_a_method_parameter_of_the_wrong_kind_is_refused_before_rendering(
        tmp_path, capsys, method, param, said):
    refused(capsys, _run(tmp_path, "--method", method, "--param", param), f"{method}: {said}")
    assert not (tmp_path / "cache").exists() and not (tmp_path / "out").exists()


@pytest.mark.parametrize("method, param, said", [
    ("asvgf", "gradient_iterations=abc", "gradient_iterations: expected an integer, got 'abc'"),
    ("asvgf", "gradient_iterations=-1", "gradient_iterations: expected an integer in [0, 12]"),
    ("asvgf", "gradient_iterations=64", "gradient_iterations: expected an integer in [0, 12]"),
    ("bmfr", "rcond=-1", "rcond: expected a finite number ≥ 0, got -1"),
    ("accumulate", "tau_d=nan", "tau_d: expected a number, got 'nan'"),
    ("accumulate", "tau_n=-5", "tau_n: expected a number in [-1, 1], got -5"),
])
def test_a_temporal_parameter_out_of_range_is_refused_before_rendering(
        tmp_path, capsys, method, param, said):
    argv = [a if a != "cornell" else "flicker" for a in _run(tmp_path)]
    refused(capsys, argv + ["--frames", "2", "--method", method, "--param", param],
            f"{method}: {said}")
    assert not (tmp_path / "cache").exists() and not (tmp_path / "out").exists()


def test_a_scene_parameter_given_twice_with_two_values_is_refused(tmp_path, capsys):
    """As --param refuses one key given two values: the last used to win without a word."""
    argv = [a if a != "cornell" else "fog-transient" for a in _run(tmp_path)]
    refused(capsys, argv + ["--method", "noisy", "--scene-param", "g=0.5", "--scene-param",
                            "g=0.2"], "--scene-param: g given twice, '0.5' and '0.2'")
    assert not (tmp_path / "cache").exists() and not (tmp_path / "out").exists()


@pytest.mark.parametrize("text", ["garbage", "[]", '{"config": 3}'])
def test_report_refuses_a_damaged_sweep_json(tmp_path, capsys, text):
    """dbench report used to publish a README of "0 method labels × spp , None px" from a
    sweep.json that is not one; it refuses it as dbench sweep does, and writes nothing."""
    sweep = tmp_path / "res" / "sw"
    sweep.mkdir(parents=True)
    (sweep / "sweep.json").write_text(text)
    err = refused(capsys, ["report", "--results", str(tmp_path / "res"), "--sweep", str(sweep)],
                  f"{sweep / 'sweep.json'}: ")
    assert "repair it or move it away" in err
    assert not (tmp_path / "res" / "README.md").exists()


def test_export_adds_spp_only_to_an_export_of_the_same_render(renderer, tmp_path, capsys):
    """The folder's scene was judged by its name alone: the same file with another
    --scene-param, an edit, or another --res added spp beside renders of another scene and
    overwrote their reference (a --res 16 export beside 8×8 files, or light=20's spp beside
    light=8's reference)."""
    scene = tmp_path / "room.xml"
    scene.write_text(lamp_scene("8"))
    out = tmp_path / "exp"
    argv = ["export", str(scene), "--out", str(out), "--ref-spp", "8", "--quiet",
            "--cache", str(tmp_path / "cache")]
    assert cli.main(argv + ["--spp", "2", "--res", "8"]) == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    refused(capsys, argv + ["--spp", "4", "--res", "8", "--scene-param", "light=20"],
            "holds an export of room.xml with fingerprint")
    refused(capsys, argv + ["--spp", "4", "--res", "16"], "--res")
    scene.write_text(lamp_scene("8").replace('value="0.5"', 'value="0.6"'))
    refused(capsys, argv + ["--spp", "4", "--res", "8"], "other content")
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    scene.write_text(lamp_scene("8"))  # the same scene again: more spp are added
    assert cli.main(argv + ["--spp", "4", "--res", "8", "--scene-param", "light=8"]) == 0
    assert (out / "room.xml_0004.hdr.exr").is_file()


def test_render_refuses_a_folders_settings_before_rendering_the_scenes_before_it(
        renderer, tmp_path, capsys):
    """dbench render took its scenes in turn: a folder of renders whose reference spp is not
    --ref-spp was refused only after the scene file listed before it had rendered."""
    scene = tmp_path / "room.xml"
    scene.write_text(lamp_scene("8"))
    folder = tmp_path / "exp"
    assert cli.main(["export", "cornell", "--out", str(folder), "--res", "8", "--spp", "2",
                     "--ref-spp", "16", "--quiet", "--cache", str(tmp_path / "c0")]) == 0
    capsys.readouterr()
    cache = tmp_path / "cache"
    refused(capsys, ["render", "--scene", f"{scene},{folder}", "--spp", "2", "--res", "8",
                     "--ref-spp", "8", "--cache", str(cache)], "--ref-spp", "16 spp")
    assert not cache.exists()
