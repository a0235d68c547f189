"""A refused sweep leaves the cache alone, ``--no-cache`` writes nothing to it, and the report's
cell counts add up (expected = ok + skipped + error + missing; other cells counted apart)."""
import json
import os
import subprocess
import sys

import pytest

from dbench import cli
from dbench.run import sweep, sweep_history
from dbench.report import verdicts


def _args(out, cache, *extra):
    return ["sweep", "--methods", "noisy", "--scenes", "cornell", "--spp", "2", "--res", "8",
            "--ref-spp", "16", "--repeats", "1", "--out", str(out), "--quiet", "--cache",
            str(cache), *extra]


def test_a_refused_sweep_does_not_create_the_cache(tmp_path, capsys):
    cache = tmp_path / "cache"
    assert cli.main(_args(tmp_path / "S", cache, "--workers", "0")) == 2
    # a folder holding a sweep of other settings
    out = tmp_path / "T"
    out.mkdir()
    other = sweep.SweepConfig(methods=["noisy"], scenes=["cornell"], spp=[2], res=16,
                              ref_spp=16, repeats=1)
    stored = sweep_history.stored_config(out, other, None)
    (out / "sweep.json").write_text(json.dumps(stored))
    assert cli.main(_args(out, cache)) == 2
    err = capsys.readouterr().err
    assert "res: 16 there, 8 now" in err
    assert not cache.exists() and not (tmp_path / "S").exists()


@pytest.mark.mitsuba
@pytest.mark.parametrize("given", [False, True])
def test_a_cache_folder_that_is_a_file_is_named_as_it_was_given(renderer, tmp_path, capsys,
                                                                monkeypatch, given):
    """$DBENCH_CACHE naming a file was refused as "--cache FILE", an option never given."""
    taken = tmp_path / "taken"
    taken.write_text("")
    if given:
        argv = _args(tmp_path / "S", taken)
    else:
        monkeypatch.setenv("DBENCH_CACHE", str(taken))
        argv = [a for a in _args(tmp_path / "S", taken) if a not in ("--cache", str(taken))]
    assert cli.main(argv) == 2
    said = f"--cache {taken}: exists and is not a folder\n" if given else \
        (f"$DBENCH_CACHE {taken}: exists and is not a folder; a sweep's workers share renders "
         f"through the cache: give --cache a writable folder\n")
    assert capsys.readouterr().err == "dbench: " + said
    assert not (tmp_path / "S").exists()


def test_no_cache_writes_nothing_to_the_cache(renderer, tmp_path):
    cache = tmp_path / "cache"
    env = {**os.environ, "DBENCH_CACHE": str(cache)}
    cmd = [sys.executable, "-m", "dbench.cli", "sweep", "--methods", "noisy,jbf", "--scenes",
           "cornell", "--spp", "2,4", "--res", "8", "--ref-spp", "16", "--repeats", "1",
           "--workers", "2", "--out", str(tmp_path / "S"), "--quiet", "--no-cache"]
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert len(sweep.load_cells(tmp_path / "S")) == 4
    # nothing at all: no render, and not the renderer probe's verdict either
    # (dbench.datasets.mitsuba_env keeps it in the process under --no-cache)
    written = {p.relative_to(cache).as_posix() for p in cache.rglob("*")} if cache.exists() \
        else set()
    assert written == set(), sorted(written)


def _cell(scene, spp, method, status="ok"):
    return {"scene": scene, "spp": spp, "method": method, "status": status}


def test_grid_counts_add_up_with_cells_outside_the_grid():
    config = {"scenes": ["cornell", "textured"], "spp": [4, 16], "labels": ["noisy"]}
    cells = [_cell("cornell", 4, "noisy"), _cell("cornell", 16, "noisy", "error"),
             _cell("textured", 4, "noisy"),
             _cell("mirrors", 4, "noisy"), _cell("cornell", 64, "noisy")]  # not in the grid
    status = verdicts.grid_status(config, cells)
    assert status["expected"] == 4 == (status["ok"] + status["skipped"] + status["error"]
                                       + status["other"] + len(status["missing"]))
    assert (status["ok"], status["error"], status["outside"]) == (2, 1, 2)
    text = verdicts.grid_status_text(status)
    assert text.startswith("cells: 4 expected, 2 ok, 0 skipped, 1 error, 1 missing; 2 more "
                           "cells outside the sweep's settings")
    # a scene file's cells are filed under its label, not its path
    files = {"scenes": ["/x/a/cbox.xml"], "spp": [4], "labels": ["noisy"],
             "scene_labels": {"/x/a/cbox.xml": "cbox.xml"}}
    status = verdicts.grid_status(files, [_cell("cbox.xml", 4, "noisy")])
    assert (status["expected"], status["ok"], status["missing"], status["outside"]) == (
        1, 1, [], 0)
    # no grid recorded: the cells there are the grid
    status = verdicts.grid_status({}, cells[:2])
    assert (status["expected"], status["ok"], status["error"], status["missing"]) == (
        2, 1, 1, [])


@pytest.mark.mitsuba
def test_worker_warnings_go_to_the_sweep_log_not_the_terminal(renderer, tmp_path):
    """A method's library warnings inside a worker process (``--workers 2``) are written to
    ``sweep.log`` and counted, as a serial sweep's are; nothing of them reaches stderr."""
    plugin = tmp_path / "warns.py"
    plugin.write_text(
        "import warnings\n"
        "from dbench.denoiser import Denoiser, register\n"
        "@register('warns')\n"
        "class Warns(Denoiser):\n"
        "    name = 'warns'\n"
        "    kinds = {'steady'}\n"
        "    needs = {'color'}\n"
        "    defaults = {}\n"
        "    def denoise(self, data):\n"
        "        warnings.warn('from inside a worker', RuntimeWarning)\n"
        "        return data.color.copy()\n")
    cmd = [sys.executable, "-m", "dbench.cli", "sweep", "--plugin", str(plugin), "--methods",
           "noisy,warns", "--scenes", "cornell", "--spp", "2,4", "--res", "8", "--ref-spp", "16",
           "--repeats", "1", "--workers", "2", "--out", str(tmp_path / "S"),
           "--cache", str(tmp_path / "c")]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "from inside a worker" not in proc.stderr + proc.stdout
    log = (tmp_path / "S" / "sweep.log").read_text(encoding="utf-8")
    assert log.count("from inside a worker") >= 2  # both groups, each in its worker
    assert "see sweep.log" in proc.stdout
