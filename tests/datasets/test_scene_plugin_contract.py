"""The scene build contract as README.md states it ("Python scene files"): the README's example
scenes are taken from the README itself and rendered, steady and transient, at a square and a
non-square size, as scene files and as an entry-point plugin; ``build(mi, res)`` written for
square images (``"width": res, "height": res``) keeps working, and a Scene object whose film
has another size than the request is refused in one line saying what to write."""
from __future__ import annotations

import os
import pickle
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from dbench import plugins
from dbench.errors import DbenchInputError
from dbench.resolution import Res, Resolution, parse_res

ROOT = Path(__file__).resolve().parents[2]
README = (ROOT / "README.md").read_text(encoding="utf-8")


def readme_examples() -> dict[str, str]:
    """{file name: code} of the README's Python blocks whose first line names a file
    (``# my_scene.py: ...``)."""
    out = {}
    for block in re.findall(r"```python\n(.*?)```", README, flags=re.S):
        m = re.match(r"#\s*([\w/]+\.py)\b", block)
        if m:
            out[m.group(1)] = block
    return out


EXAMPLES = readme_examples()


def _entry_point() -> tuple[str, str]:
    """(name, target) of the README's ``dbench.scenes`` entry point (the TOML block)."""
    m = re.search(r'\[project\.entry-points\."dbench\.scenes"\]\s*\n\s*([\w-]+)\s*=\s*'
                  r'"([\w.]+:\w+)"', README)
    assert m, "README: no dbench.scenes entry point"
    return m.group(1), m.group(2)


def _old_form(code: str) -> str:
    """A README example rewritten as a scene written when ``res`` was one side."""
    code = code.replace("def build(mi, width, height):", "def build(mi, res):")
    code = re.sub(r"width=width, height=height", "width=res, height=res", code)
    return re.sub(r'"width": width, "height": height', '"width": res, "height": res', code)


def _load(scene, res, tmp_path, **kw):
    from dbench import datasets

    return datasets.load(scene, spp=2, res=res, ref_spp=16, cache=datasets.Cache(
        tmp_path / "cache"), needs={"color", "reference"}, progress=False, **kw)


SIZES = [8, "12x8"]


# ---------------------------------------------------------------------------------------------
# no rendering


def test_the_readme_shows_both_signatures_and_the_examples():
    assert {"my_scene.py", "my_pulse.py", "my_package/scenes.py"} <= set(EXAMPLES)
    assert "def build(mi, width, height):" in EXAMPLES["my_scene.py"]
    assert 'kind = "transient"' in EXAMPLES["my_pulse.py"]
    assert "def my_room(mi, res):" in EXAMPLES["my_package/scenes.py"]
    assert _entry_point() == ("my-room", "my_package.scenes:my_room")
    text = " ".join(README.split())
    assert "`build(mi, width, height)` (two ints), or `build(mi, res)`" in text
    assert "unpacks as `width, height = res`" in text


def test_resolution_is_the_width_and_unpacks_as_the_size():
    r = Resolution(12, 8)
    assert int(r) == 12 and r == 12 and r.width == 12 and r.height == 8
    assert tuple(r) == (12, 8) and r[1] == 8 and len(r) == 2
    w, h = r
    assert (w, h) == (12, 8) and str(r) == "12x8" and r.key == "12x8" and r.pixels == 96
    assert parse_res(r) == Res(12, 8)  # dbench's helpers keep the height
    assert pickle.loads(pickle.dumps(r)) == r and pickle.loads(pickle.dumps(r)).height == 8
    assert r != Resolution(12, 12) and Resolution(8, 8) == 8 and str(Resolution(8, 8)) == "8"
    assert {"width": Resolution(8, 8)}["width"] + 1 == 9


def test_the_signature_decides_the_form():
    from dbench.datasets.scenes.build import takes_width_height

    def a(mi, width, height): ...
    def b(mi, res): ...
    def c(mi, res, extra=None): ...
    def d(mi, width, height=None): ...
    def e(mi, w, h): ...
    assert takes_width_height(a) and takes_width_height(d) and takes_width_height(e)
    assert not takes_width_height(b) and not takes_width_height(c)


# ---------------------------------------------------------------------------------------------
# the README's scene files, rendered


@pytest.mark.mitsuba
@pytest.mark.parametrize("form", ["readme", "build(mi, res)"])
@pytest.mark.parametrize("res", SIZES)
def test_the_readme_steady_scene_file_renders(renderer, tmp_path, form, res):
    from dbench.datasets.scene_files import load as scene_files

    code = EXAMPLES["my_scene.py"]
    path = tmp_path / "my_scene.py"
    path.write_text(code if form == "readme" else _old_form(code))
    assert ("def build(mi, res)" in path.read_text()) == (form != "readme")
    frame = _load(scene_files.resolve(path), res, tmp_path)
    size = parse_res(res)
    assert frame.color.shape == (size.height, size.width, 3)
    assert np.isfinite(frame.color).all() and frame.reference.mean() > 0


@pytest.mark.mitsuba
@pytest.mark.parametrize("form", ["readme", "build(mi, res)"])
@pytest.mark.parametrize("res", SIZES)
def test_the_readme_transient_scene_file_renders(tr, tmp_path, form, res):
    from dbench.datasets.scene_files import load as scene_files

    code = EXAMPLES["my_pulse.py"]
    path = tmp_path / "my_pulse.py"
    path.write_text(code if form == "readme" else _old_form(code))
    sc = scene_files.resolve(path)
    assert sc.kind == "transient" and sc.default_bins == 100
    frame = _load(sc, res, tmp_path, bins=6)
    size = parse_res(res)
    assert frame.color.shape == (size.height, size.width, 6, 3)
    assert frame.reference.sum() > 0


# ---------------------------------------------------------------------------------------------
# the README's entry-point plugin, installed the way pip would


def _install(site: Path, code: str) -> dict:
    """The README's my_package and a dist-info folder declaring its entry point, on
    PYTHONPATH."""
    name, target = _entry_point()
    pkg = site / "my_package"
    pkg.mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "scenes.py").write_text(code)
    info = site / "my_package-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: my-package\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(f"[dbench.scenes]\n{name} = {target}\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(site)] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p])}
    env.pop(plugins.ENV_VAR, None)
    return env


@pytest.mark.mitsuba
def test_the_readme_entry_point_scene_runs_at_any_size(renderer, tmp_path):
    env = _install(tmp_path / "site", EXAMPLES["my_package/scenes.py"])
    env["DBENCH_CACHE"] = str(tmp_path / "cache")

    def dbench(*args):
        return subprocess.run([sys.executable, "-m", "dbench.cli", *args], env=env,
                              cwd=tmp_path, capture_output=True, text=True, timeout=600)

    listed = dbench("list")
    assert listed.returncode == 0, listed.stderr
    assert any(ln.split()[:2] == ["my-room", "steady"] and "Mitsuba's Cornell box" in ln
               for ln in listed.stdout.splitlines()), listed.stdout
    for res in ("8", "12x8"):
        out = tmp_path / f"run-{res}"
        ran = dbench("run", "--method", "noisy", "--scene", "my-room", "--res", res, "--spp",
                     "2", "--ref-spp", "16", "--repeats", "1", "--quiet", "--out", str(out))
        assert ran.returncode == 0, ran.stderr
        row = (out / "metrics.csv").read_text().splitlines()[1].split(",")
        assert row[:2] == ["my-room", "noisy"] and res in row, row


@pytest.mark.mitsuba
def test_the_readme_plugin_scene_object_runs(renderer, tmp_path):
    """README.md, "Python scene files": the Scene a plugin file registers, with its own
    max_depth, runs through --plugin at a non-square size."""
    plugin = tmp_path / "my_scenes.py"
    plugin.write_text(EXAMPLES["my_scenes.py"])
    env = {**os.environ, "DBENCH_CACHE": str(tmp_path / "cache")}
    out = tmp_path / "run"
    ran = subprocess.run([sys.executable, "-m", "dbench.cli", "--plugin", str(plugin), "run",
                          "--method", "noisy", "--scene", "my-box", "--res", "12x8", "--spp",
                          "2", "--ref-spp", "16", "--repeats", "1", "--quiet", "--out",
                          str(out)], env=env, cwd=tmp_path, capture_output=True, text=True,
                         timeout=600)
    assert ran.returncode == 0, ran.stderr
    row = (out / "metrics.csv").read_text().splitlines()[1].split(",")
    assert row[:2] == ["my-box", "noisy"], row


@pytest.mark.mitsuba
@pytest.mark.parametrize("res", SIZES)
def test_entry_point_builds_in_both_forms_render(renderer, tmp_path, res):
    """What an entry point registers: the README's function, the same written with
    ``"width": res, "height": res`` (a scene from before non-square sizes) and the three-int
    form."""
    from dbench.datasets.scenes import catalogue as scenes

    namespace: dict = {}
    exec(EXAMPLES["my_package/scenes.py"], namespace)

    def square_style(mi, res):
        d = mi.cornell_box()
        d["sensor"]["film"].update({"width": res, "height": res})
        return d

    def three_ints(mi, width, height):
        d = mi.cornell_box()
        d["sensor"]["film"].update(width=width, height=height)
        return d

    before = dict(scenes._CATALOGUE)
    try:
        size = parse_res(res)
        for name, fn in (("readme-room", namespace["my_room"]),
                         ("square-style-room", square_style), ("three-int-room", three_ints)):
            plugins._register_scene_object(name, fn)
            plugins._register_scene_object(name, fn)  # twice: once
            frame = _load(scenes.get(name), res, tmp_path)
            assert frame.color.shape == (size.height, size.width, 3), name
    finally:
        scenes._CATALOGUE.clear()
        scenes._CATALOGUE.update(before)


# ---------------------------------------------------------------------------------------------
# Scene objects render their dictionary as it is: the film must have the requested size


@pytest.mark.mitsuba
def test_a_scene_object_with_a_square_film_for_a_wide_request_is_refused(renderer, tmp_path):
    from dbench.datasets.scenes.record import Scene
    from dbench.datasets.scenes.catalogue import cornell

    def build(mi, res):
        d = cornell(mi, 8)
        d["sensor"]["film"].update({"width": res, "height": res})
        return d

    sc = Scene(name="square-only", kind="steady", description="x", build=build)
    assert _load(sc, 8, tmp_path).color.shape == (8, 8, 3)  # square sizes: as before
    with pytest.raises(DbenchInputError) as exc:
        _load(sc, "12x8", tmp_path)
    message = str(exc.value)
    assert "\n" not in message and "square-only" in message and "12×12 film" in message
    assert f"({__file__})" in message  # the file the build function is in
    assert '"width": res.width, "height": res.height' in message


@pytest.mark.mitsuba
def test_a_transient_scene_object_in_the_square_form_renders(tr, tmp_path):
    from dbench.datasets.scenes.catalogue import cornell
    from dbench.datasets.transient.scene import TransientScene

    def build(mi, res):
        d = cornell(mi, 8)
        d["sensor"]["film"].update({"width": res, "height": res})
        return d

    sc = TransientScene(name="my-square-pulse", kind="transient", description="x",
                        build=build, window_start=3.8, window_end=11.5, default_bins=6)
    frame = _load(sc, 8, tmp_path)
    assert frame.color.shape == (8, 8, 6, 3) and frame.reference.sum() > 0
    with pytest.raises(DbenchInputError, match="res.width"):
        _load(sc, "12x8", tmp_path)


@pytest.mark.mitsuba
def test_a_plugin_scene_naming_an_unknown_mitsuba_type_is_refused_before_rendering(
        renderer, tmp_path):
    """A plugin's scene is loaded once at 8 px before its first render: a type Mitsuba has no
    plugin for is one line naming the scene, the entry and the type, and no cache entry."""
    from dbench.datasets.scenes import catalogue as scenes

    def blob_room(mi, res):
        d = mi.cornell_box()
        d["sensor"]["film"].update(width=res.width, height=res.height)
        d["blob"] = {"type": "spherez"}
        return d

    before = dict(scenes._CATALOGUE)
    try:
        plugins._register_scene_object("blob-room", blob_room)
        with pytest.raises(DbenchInputError) as exc:
            _load(scenes.get("blob-room"), 8, tmp_path)
    finally:
        scenes._CATALOGUE.clear()
        scenes._CATALOGUE.update(before)
    message = str(exc.value)
    assert "\n" not in message and message.startswith("scene blob-room: ")
    assert '"spherez"' in message and '"blob"' in message
    assert not any(p.is_dir() for p in (tmp_path / "cache").glob("*/*"))


PLUGIN_RECORD = '''
from dbench.datasets.scenes.record import Scene, register_scene

def build(mi, res):
    d = mi.cornell_box()
    d["sensor"]["film"].update(width=res.width, height=res.height, rfilter={"type": "box"})
    return d

register_scene(Scene(name="%s", kind="steady", description="x", build=build, %s))
'''


@pytest.mark.parametrize("field, said", [
    ('ev=float("inf")', "Scene ev: expected a finite number"),
    ("ev=1e6", "in [-1074, 1023], got 1000000.0"),
    ("max_depth=0", "Scene max_depth 0; give -1 (unlimited) or an integer of 1 or more")])
def test_a_plugin_scene_records_exposure_and_depth_are_checked_before_rendering(
        isolated, renderer, tmp_path, capsys, field, said):
    """A plugin's Scene(ev=inf) or ev=1e6 failed in the metrics after every method ran (1e6:
    an internal OverflowError), and max_depth=0 rendered a black reference, refused only
    afterwards as unlit."""
    from dbench.cli import main
    plugin = tmp_path / "record_plugin.py"
    plugin.write_text(PLUGIN_RECORD % ("odd-box", field))
    rc = main(["--plugin", str(plugin), "run", "--method", "noisy", "--scene", "odd-box",
               "--res", "8", "--spp", "1", "--ref-spp", "8", "--out", str(tmp_path / "out"),
               "--cache", str(tmp_path / "cache")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "scene odd-box (" in err[0] and said in err[0], err
    assert not (tmp_path / "out").exists() and not (tmp_path / "cache").exists()
