"""Mitsuba's own log lines (dbench/datasets/mitsuba_log.py) and the other libraries' warnings
(dbench/run/capture.py): kept in ``run.log`` / ``sweep.log`` and counted in ``report.md``, on
the terminal only without ``--quiet`` (README.md, "Usage")."""
from __future__ import annotations

import logging

import pytest

from dbench.cli import main
from dbench.run.capture import count_text, library_warnings, log_text

#: A scene file Mitsuba loads with a warning (the film's removed "compensate" parameter).
XML = """<scene version="3.0.0">
  <sensor type="perspective"><float name="fov" value="50"/>
    <transform name="to_world"><lookat origin="0,1.2,4" target="0,0.3,0" up="0,1,0"/></transform>
    <film type="hdrfilm"><boolean name="compensate" value="true"/>
      <integer name="width" value="12"/><integer name="height" value="12"/></film>
  </sensor>
  <shape type="sphere"><point name="center" x="0" y="0.5" z="0"/><float name="radius" value="0.5"/>
    <bsdf type="diffuse"/></shape>
  <emitter type="constant"><rgb name="radiance" value="1"/></emitter>
</scene>
"""
WARNED = '"compensate"'
TINY = ["--spp", "2", "--res", "12", "--ref-spp", "16", "--repeats", "1"]


@pytest.mark.mitsuba
@pytest.mark.parametrize("quiet", [True, False])
def test_a_scene_files_mitsuba_warning_is_kept_and_shown_only_without_quiet(
        renderer, tmp_path, capfd, quiet):
    scene = tmp_path / "warns.xml"
    scene.write_text(XML)
    out = tmp_path / "run"
    assert main(["run", "--scene", str(scene), "--method", "noisy", *TINY,
                 "--cache", str(tmp_path / "cache"), "--out", str(out)]
                + (["--quiet"] if quiet else [])) == 0
    cap = capfd.readouterr()  # the descriptors: Mitsuba printed from C++ before
    shown = [ln for ln in (cap.out + cap.err).splitlines() if WARNED in ln]
    assert shown == ([] if quiet else [
        'mitsuba warning: [HDRFilm] The "compensate" (Kahan-style error-compensated '
        'accumulation) parameter has been removed and is now ignored.'])
    log = (out / "run.log").read_text(encoding="utf-8").splitlines()
    kept = [ln for ln in log if WARNED in ln]
    assert len(kept) == 1 and kept[0].startswith("WARNING mitsuba: [HDRFilm] The ")
    assert log[0] == "1 library warning"
    assert "1 library warning, see run.log." in (out / "report.md").read_text(encoding="utf-8")


@pytest.mark.mitsuba
def test_a_quiet_sweep_keeps_the_mitsuba_warning_in_its_log_once(renderer, tmp_path, capfd):
    scene = tmp_path / "warns.xml"
    scene.write_text(XML)
    assert main(["sweep", "--scenes", str(scene), "--methods", "noisy", *TINY, "--quiet",
                 "--cache", str(tmp_path / "cache"), "--out", str(tmp_path / "S")]) == 0
    cap = capfd.readouterr()
    assert WARNED not in cap.out + cap.err
    log = (tmp_path / "S" / "sweep.log").read_text(encoding="utf-8")
    assert log.count(WARNED) == 1, log


@pytest.mark.mitsuba
@pytest.mark.parametrize("workers", ["1", "2"])
def test_a_scene_file_swept_beside_another_scene_warns_once(renderer, tmp_path, capfd,
                                                             workers):
    """The file is read when the sweep checks its scenes, then cornell's reference drops its
    objects (mitsuba_env.focus) and its renders load it again, in the sweep's process or in a
    pool worker: the same warnings, kept and shown once (mitsuba_log.loading)."""
    scene = tmp_path / "warns.xml"
    scene.write_text(XML)
    assert main(["sweep", "--scenes", f"cornell,{scene}", "--methods", "noisy", *TINY,
                 "--workers", workers, "--cache", str(tmp_path / "cache"),
                 "--out", str(tmp_path / "S")]) == 0
    cap = capfd.readouterr()
    assert (cap.out + cap.err).count(WARNED) == 1
    log = (tmp_path / "S" / "sweep.log").read_text(encoding="utf-8")
    assert log.count(WARNED) == 1 and log.startswith("1 library warning\n"), log


@pytest.mark.mitsuba
def test_a_scene_file_swept_on_ray_warns_once(renderer, tmp_path):
    """A Ray task loads the file again, as a pool worker does (sweep_pool.execute)."""
    ray = pytest.importorskip("ray")
    scene = tmp_path / "warns.xml"
    scene.write_text(XML)
    try:
        ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
        assert main(["sweep", "--scenes", f"cornell,{scene}", "--methods", "noisy", *TINY,
                     "--executor", "ray", "--quiet", "--cache", str(tmp_path / "cache"),
                     "--out", str(tmp_path / "S")]) == 0
    finally:
        ray.shutdown()
    log = (tmp_path / "S" / "sweep.log").read_text(encoding="utf-8")
    assert log.count(WARNED) == 1, log


@pytest.mark.mitsuba
def test_each_command_keeps_the_warnings_of_its_own_loads(renderer, tmp_path):
    """Commands in one process (a notebook): the file loaded again by a later command, after
    another scene's dropped its objects, still has its warnings in that command's log."""
    scene = tmp_path / "warns.xml"
    scene.write_text(XML)
    common = ["--method", "noisy", *TINY, "--quiet", "--no-cache"]  # each renders
    for k, name in enumerate([str(scene), "cornell", str(scene)]):
        assert main(["run", "--scene", name, *common, "--out", str(tmp_path / f"r{k}")]) == 0
    for k in (0, 2):
        log = (tmp_path / f"r{k}" / "run.log").read_text(encoding="utf-8")
        assert log.count(WARNED) == 1, (k, log)


def test_a_repeated_or_inherited_load_drops_its_warnings_and_keeps_its_errors(monkeypatch):
    """dbench/datasets/mitsuba_log.py: the innermost load decides; an error always passes; a
    pool worker drops, in its loads only, the lines the sweep process's loads forwarded."""
    from types import SimpleNamespace

    from dbench.datasets import mitsuba_log as ml

    mi = SimpleNamespace(LogLevel=SimpleNamespace(Warn=3, Error=4))
    monkeypatch.setattr(ml, "_load_lines", [])
    monkeypatch.setattr(ml, "_inherited", set())
    with library_warnings() as caught:
        with ml.loading():
            ml.forward(mi, 3, "first")
            with ml.loading(again=True):
                ml.forward(mi, 3, "first")  # a repeat inside a first load: dropped
                ml.forward(mi, 4, "broken")
            ml.forward(mi, 3, "outer")
        with ml.loading(again=True):
            with ml.loading():  # a first load inside a repeated one: its own lines pass
                ml.forward(mi, 3, "new")
        assert ml.load_lines() == ("first", "outer", "new")
        ml.inherit(["outer"])
        with ml.loading():
            ml.forward(mi, 3, "outer")
        ml.forward(mi, 3, "outer")  # outside a load (a render's warning): forwarded
    assert caught == ["WARNING mitsuba: first", "ERROR mitsuba: broken",
                      "WARNING mitsuba: outer", "WARNING mitsuba: new", "WARNING mitsuba: outer"]


def test_one_warning_is_one_warning_in_the_log_and_the_count():
    assert log_text(["x"]).splitlines()[0] == "1 library warning"
    assert log_text(["x", "y"]).splitlines()[0] == "2 library warnings"
    assert count_text(["x"]) == "1 library warning, see run.log"
    assert log_text([]) == "no library warnings\n"


def test_nested_blocks_keep_a_logging_record_once():
    """A serial sweep runs each group inside its own block, inside the sweep's: the innermost
    keeps the record (the sweep then gets it from the group's lines), so sweep.log holds a
    library's logging warning once, not twice."""
    with library_warnings() as outer:
        with library_warnings() as inner:
            logging.getLogger("some.library").warning("once")
        logging.getLogger("some.library").warning("after")
    assert inner == ["WARNING some.library: once"]
    assert outer == ["WARNING some.library: after"]


@pytest.mark.mitsuba
def test_a_quiet_export_keeps_the_mitsuba_warning_in_export_log(renderer, tmp_path, capfd):
    scene = tmp_path / "warns.xml"
    scene.write_text(XML)
    out = tmp_path / "folder"
    assert main(["export", str(scene), "--out", str(out), "--spp", "2", "--res", "12",
                 "--ref-spp", "16", "--cache", str(tmp_path / "cache"), "--quiet"]) == 0
    cap = capfd.readouterr()
    assert WARNED not in cap.out + cap.err
    log = (out / "export.log").read_text(encoding="utf-8").splitlines()
    assert log[0] == "1 library warning" and WARNED in log[1], log
    assert f"1 library warning, see {out / 'export.log'}" in cap.out


#: A method that loads the scene file above each time it runs: Mitsuba warns while stress runs.
PLUGIN = f'''
import numpy as np
from dbench.registry import Denoiser, register

@register("loads-xml")
class LoadsXml(Denoiser):
    kinds = {{"steady"}}
    needs = {{"color"}}

    def denoise(self, data):
        from dbench.datasets.mitsuba_env import mitsuba
        mitsuba().load_string({XML!r})
        return np.asarray(data.color, dtype=np.float32)
'''


@pytest.mark.mitsuba
def test_a_quiet_stress_keeps_the_mitsuba_warnings_in_stress_log(renderer, isolated, tmp_path,
                                                                 capfd):
    plugin = tmp_path / "loads_xml.py"
    plugin.write_text(PLUGIN)
    out = tmp_path / "stress.md"
    assert main(["--plugin", str(plugin), "stress", "--methods", "loads-xml", "--out", str(out),
                 "--quiet"]) in (0, 4)
    cap = capfd.readouterr()
    assert WARNED not in cap.out + cap.err
    log = (tmp_path / "stress.log").read_text(encoding="utf-8")
    n = log.count(WARNED)
    assert n >= 1 and log.splitlines()[0].endswith(("library warning", "library warnings"))
    assert f"on the hostile inputs: {log.splitlines()[0]}, see {tmp_path / 'stress.log'}" \
        in cap.out


#: Dr.Jit's start-up warning where its kernel cache folder cannot be made (a file stands in its
#: path), printed by Dr.Jit from C++ while it is imported.
JIT_WARNED = "jit_init(): could not use"


@pytest.mark.mitsuba
@pytest.mark.parametrize("quiet", [True, False])
def test_dr_jits_start_up_warning_is_kept_and_shown_only_without_quiet(renderer, tmp_path, quiet):
    import os
    import subprocess
    import sys
    from pathlib import Path

    scene = tmp_path / "warns.xml"
    scene.write_text(XML)
    (tmp_path / "a-file").write_text("")
    env = {**os.environ, "DRJIT_CACHE_DIR": str(tmp_path / "a-file" / "kernels")}
    out = tmp_path / "run"
    r = subprocess.run([sys.executable, "-m", "dbench", "run", "--scene", str(scene), "--method",
                        "noisy", *TINY, "--cache", str(tmp_path / "cache"), "--out", str(out)]
                       + (["--quiet"] if quiet else []), env=env, capture_output=True, text=True,
                       timeout=600, cwd=Path(__file__).resolve().parents[2])
    assert r.returncode == 0, r.stderr
    shown = [ln for ln in (r.stdout + r.stderr).splitlines() if JIT_WARNED in ln]
    assert len(shown) == (0 if quiet else 1), r.stderr
    assert all(ln.startswith(JIT_WARNED) for ln in shown)  # as Dr.Jit words it
    log = (out / "run.log").read_text(encoding="utf-8").splitlines()
    kept = [ln for ln in log if JIT_WARNED in ln]
    assert len(kept) == 1 and kept[0].startswith(f"WARNING drjit: {JIT_WARNED}"), log


@pytest.mark.mitsuba
@pytest.mark.parametrize("quiet", [True, False])
def test_a_quiet_command_has_dr_jit_print_its_errors_alone(renderer, tmp_path, monkeypatch,
                                                           request, quiet):
    """Dr.Jit's warnings after its import (its memory cache flushed) reach no terminal under
    --quiet: its own level is errors alone while the command runs, and after it the level it
    found (here a notebook's Info)."""
    import drjit as dr

    mine = dr.log_level()
    dr.set_log_level(dr.LogLevel.Info)
    request.addfinalizer(lambda: dr.set_log_level(mine))

    from dbench.methods.noisy import Noisy

    levels = []
    denoise = Noisy.denoise
    monkeypatch.setattr(Noisy, "denoise",
                        lambda self, data: levels.append(dr.log_level()) or denoise(self, data))
    scene = tmp_path / "warns.xml"
    scene.write_text(XML)
    assert main(["run", "--scene", str(scene), "--method", "noisy", *TINY,
                 "--cache", str(tmp_path / "cache"), "--out", str(tmp_path / "run")]
                + (["--quiet"] if quiet else [])) == 0
    assert levels and set(levels) == {dr.LogLevel.Error if quiet else dr.LogLevel.Warn}
    assert dr.log_level() == dr.LogLevel.Info
