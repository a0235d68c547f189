"""Sweeps: one file per cell, skips recorded, resume after a kill, Ray executor, report."""
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from dbench.report import publish
from dbench.run import sweep

pytestmark = pytest.mark.mitsuba


def _config(tmp_path, **kw):
    base = dict(methods=["noisy", "oidn"], scenes=["cornell", "textured"], spp=[2, 4], res=12,
                ref_spp=16, repeats=1, cache=str(tmp_path / "cache"))
    base.update(kw)
    return sweep.SweepConfig(**base)


def _cell_files(out):
    """The finished cell files: not the hidden ``.NAME.json.*.tmp.json`` of a write under way
    (dbench.io.atomic_path), which a killed sweep leaves and the next run deletes."""
    return [p for p in Path(out).glob("cells/*/*/*.json") if not p.name.startswith(".")]


def _mtimes(out):
    return {p: p.stat().st_mtime_ns for p in _cell_files(out)}


def test_sweep_writes_one_cell_per_file_and_resumes(renderer, tmp_path):
    out = tmp_path / "sweep"
    cfg = _config(tmp_path)
    counts = sweep.run_sweep(cfg, out, progress=False)
    assert counts == {"computed": 8, "skipped": 0, "finished_before": 0, "errors": 0,
                      "error_cells": []}
    cells = sweep.load_cells(out)
    assert len(cells) == 8 and all(c["status"] == "ok" for c in cells)
    from dbench.run.machine import machine_label
    from dbench.report.cells import machines_text

    # every cell and run records where it was timed
    assert all(c["machine"] == machine_label() for c in cells)
    # and what rendered its inputs (the variant this process renders with)
    from dbench.datasets.mitsuba_env import current_variant
    assert {c["render_variant"] for c in cells} == {current_variant()}
    assert sweep.read_cell(out / "sweep.json")["runs"][-1]["machine"] == machine_label()
    assert machines_text(cells) == [f"cells timed on {machine_label()} (8)"]
    assert machines_text(cells + [{"status": "skipped"}]) == machines_text(cells)
    mixed = machines_text(cells + [{"time_s": 1.0}])
    assert "not recorded (1)" in mixed[0] and "do not compare" in mixed[0]
    before = _mtimes(out)
    again = sweep.run_sweep(cfg, out, progress=False)
    assert again["computed"] == 0 and again["finished_before"] == 8
    assert _mtimes(out) == before
    with pytest.raises(ValueError, match="other settings"):
        sweep.run_sweep(_config(tmp_path, res=16), out, progress=False)
    # Extending with another spp computes only the new cells and keeps the old ones.
    more = sweep.run_sweep(_config(tmp_path, spp=[8]), out, progress=False)
    assert more["computed"] == 4 and more["finished_before"] == 0
    assert len(sweep.load_cells(out)) == 12 and _mtimes(out).items() >= before.items()
    stored = sweep.read_cell(out / "sweep.json")["config"]
    assert stored["spp"] == [2, 4, 8]


def test_killed_sweep_completes_with_exactly_one_result_per_cell(renderer, tmp_path):
    out = tmp_path / "killed"
    env = {**os.environ, "DBENCH_CACHE": str(tmp_path / "cache")}
    cmd = [sys.executable, "-m", "dbench.cli", "sweep", "--methods", "noisy,oidn",
           "--scenes", "cornell,textured,mirrors", "--spp", "2,4,8", "--res", "12",
           "--ref-spp", "16", "--repeats", "1", "--out", str(out), "--quiet"]
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 120
    while time.time() < deadline and len(_cell_files(out)) < 3:
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    finished = _mtimes(out)
    assert 0 < len(finished) < 18
    rc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)
    assert rc.returncode == 0, rc.stderr[-2000:]
    files = _cell_files(out)
    assert len(files) == 18 and len({f for f in files}) == 18
    for p, t in finished.items():
        assert p.stat().st_mtime_ns == t  # finished cells were not recomputed
    assert not list(out.rglob(".*.tmp*"))
    # the killed run never wrote its end: the next one records it with the cells it left
    killed, last = json.loads((out / "sweep.json").read_text())["runs"]
    assert killed["status"] == "killed" and killed["cells"] == len(finished), killed
    assert last["status"] == "finished" and last["cells"] == 18 - len(finished)


def test_skipped_pairs_are_recorded(renderer, tmp_path):
    from dbench.registry import Denoiser, register, _REGISTRY

    @register("needs-motion-test")
    class NeedsMotion(Denoiser):
        kinds = {"sequence"}
        needs = {"color"}
        defaults = {}

        def denoise(self, data):
            return data.color

    try:
        out = tmp_path / "skip"
        sweep.run_sweep(_config(tmp_path, methods=["noisy", "needs-motion-test"],
                                scenes=["cornell"], spp=[2]), out, progress=False)
        cell = sweep.read_cell(sweep.cell_path(out, "cornell", 2, "needs-motion-test"))
        assert cell["status"] == "skipped" and "sequence" in cell["reason"]
    finally:
        _REGISTRY.pop("needs-motion-test")


def test_ray_executor_on_a_local_instance(renderer, tmp_path):
    ray = pytest.importorskip("ray")
    out = tmp_path / "ray"
    try:
        ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False,
                 runtime_env={"env_vars": {"DBENCH_CACHE": str(tmp_path / "cache")}})
        counts = sweep.run_sweep(_config(tmp_path, scenes=["cornell"]), out, executor="ray",
                                 progress=False)
    finally:
        ray.shutdown()
    assert counts["computed"] == 4 and counts["errors"] == 0
    assert len(sweep.load_cells(out)) == 4
    # two groups, a node of 2 CPUs: each cell was timed beside the other group's task
    assert {c.get("timed_beside") for c in sweep.load_cells(out)} == {1}


def test_report_is_reproducible_byte_for_byte(renderer, tmp_path):
    results = tmp_path / "results"
    sweep.run_sweep(_config(tmp_path, spp=[2, 4, 8]), results / "sweep", progress=False)
    (results / "stress.md").write_text("# dbench stress test\n\n1 passed, 0 failed\n")
    first = publish.publish(results).read_bytes()
    second = publish.publish(results).read_bytes()
    assert first == second
    text = first.decode()
    for needle in ("## Headline", "## Convergence", "## Error against time",
                   "error_time_relmse.png",
                   "## Stress test", "## Environment", "relMSE"):
        assert needle in text or needle.lower() in text.lower()
    assert (results / "sweep" / "tables" / "convergence_rmse.csv").exists()


def test_sequence_and_transient_scenes_in_one_sweep(renderer, tmp_path):
    """A sequence cell runs the method once over the frames (means after the warm-up, plus the
    temporal stability); a transient cell scores the whole video; inapplicable pairs skip."""
    out = tmp_path / "results" / "sweep-kinds"
    cfg = _config(tmp_path, methods=["noisy", "accumulate", "gauss3d"],
                  scenes=["flicker", "cornell-transient"], spp=[1], res=12, ref_spp=8,
                  frames=10, bins=12)
    counts = sweep.run_sweep(cfg, out, progress=False)
    assert counts["errors"] == 0 and counts["finished_before"] == 0
    assert counts["computed"] == 4 and counts["skipped"] == 2  # gauss3d, accumulate
    seq = {m: sweep.read_cell(sweep.cell_path(out, "flicker", 1, m))
           for m in ("noisy", "accumulate", "gauss3d")}
    assert seq["gauss3d"]["status"] == "skipped" and "sequence" in seq["gauss3d"]["reason"]
    for m in ("noisy", "accumulate"):
        c = seq[m]
        assert c["status"] == "ok" and c["frames"] == 10 and c["warmup"] == 8
        assert len(c["times_s"]) == 2  # frames 8 and 9
        for k in ("rmse", "ssim", "flip", "t_rmse", "tpsnr"):
            assert k in c and c[k] == c[k]  # present and not NaN
    # Accumulating 1-spp frames of a static camera must beat the single frame it starts from.
    assert seq["accumulate"]["rmse"] < seq["noisy"]["rmse"]
    tr = {m: sweep.read_cell(sweep.cell_path(out, "cornell-transient", 1, m))
          for m in ("noisy", "accumulate", "gauss3d")}
    assert tr["accumulate"]["status"] == "skipped"
    assert tr["gauss3d"]["status"] == "ok" and tr["noisy"]["status"] == "ok"
    stored = sweep.read_cell(out / "sweep.json")["config"]
    assert stored["frames"] == 10 and stored["bins"] == 12
    with pytest.raises(ValueError, match="frames"):
        sweep.run_sweep(_config(tmp_path, methods=["noisy"], scenes=["flicker"], spp=[1],
                                res=12, ref_spp=8, frames=6, bins=12), out, progress=False)
    # The report shows a sweep beside the main one as its own section.
    sweep.run_sweep(_config(tmp_path, methods=["noisy"], scenes=["cornell"], spp=[2]),
                    tmp_path / "results" / "sweep", progress=False)
    text = publish.publish(tmp_path / "results").read_text()
    assert "## Sweep `sweep-kinds`" in text and "first 10 frames" in text
    assert "### TPSNR (rows scene/method, columns spp)" in text
    assert "| flicker | accumulate |" in text and "| cornell-transient | gauss3d |" in text


def test_a_resumed_sweep_removes_the_temporary_files_of_a_killed_one(tmp_path):
    """A run killed between writing a cell's temporary file and renaming it leaves the file;
    the next run deletes it before planning, and nothing else."""
    cell_dir = tmp_path / "cells" / "cornell" / "00004spp"
    cell_dir.mkdir(parents=True)
    stale = cell_dir / ".oidn.json.x1y2z3.tmp.json"
    stale.write_text('{"half": ')
    kept = cell_dir / "noisy.json"
    kept.write_text("{}")
    assert sweep.remove_interrupted_writes(tmp_path) == 1
    assert not stale.exists() and kept.exists()
    assert sweep.remove_interrupted_writes(tmp_path) == 0
