"""Where methods run (dbench/device.py, docs/gpu.md §3): the ``--device`` choice, frames uploaded
once, the harness's device route and what a cell records, the sweep identity, and the
``bench gpu`` script as a dry run on CPU tensors. These machines have no GPU: the device route is
exercised with CPU tensors, which is the same code with ``device="cpu"`` where it copies."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from dbench import device as dev
from dbench.run import harness, sweep
from dbench.synthetic import base_frame
from dbench.cli import main
from dbench.errors import DbenchInputError
from dbench.registry import get
from methods.device_checks import host_conversions_refused  # tests/ is on sys.path


def test_device_choices_are_checked():
    with pytest.raises(DbenchInputError, match="device: expected one of"):
        dev.resolve_device("gpu")
    if not dev.cuda_usable():
        assert dev.resolve_device("auto") == "cpu"
        with pytest.raises(DbenchInputError, match="no usable CUDA GPU"):
            dev.resolve_device("cuda")


@pytest.mark.skipif(dev.cuda_usable(), reason="checks the refusal on a machine without a GPU")
def test_cuda_without_a_gpu_is_one_line_and_exit_2(capsys, tmp_path):
    code = main(["run", "--method", "jbf", "--scene", "cornell", "--spp", "4", "--res", "16",
                 "--device", "cuda", "--out", str(tmp_path / "run")])
    err = capsys.readouterr().err
    assert code == 2 and "device" in err and "Traceback" not in err
    assert not (tmp_path / "run").exists()
    assert main(["bench", "gpu"]) == 2
    assert "no usable CUDA GPU" in capsys.readouterr().err


def test_upload_keeps_buffers_and_statistics():
    f = base_frame(6, 7)
    d = dev.upload(f, "cpu")
    assert d.shape == (6, 7) and d.kind == "steady" and "reference" not in d.buffers
    assert d.color.dtype == torch.float32 and d.stats.mean.dtype == torch.float64
    assert np.allclose(d.stats.theta.numpy(), f.stats.theta)
    assert dev.download(d.color).flags["C_CONTIGUOUS"]
    only = dev.upload(f, "cpu", {"color", "normal"})
    assert set(only.buffers) == {"color", "normal"} and only.stats is None


def test_the_harness_runs_a_device_path_and_records_where(monkeypatch):
    """The device route of run_cell (upload once, synchronised calls, download once, copies
    timed apart) on CPU tensors: placement says 'on the device' for a method with a device
    path; the output equals the host path's within the kernel's tolerance."""
    monkeypatch.setattr(harness, "placement",
                        lambda m, d: (d != "cpu" and m.runs_on_device(), "cpu"))
    f = base_frame(8, 10)
    host = harness.run_cell(get("jbf", radius=1), f, repeats=1)
    on_dev = harness.run_cell(get("jbf", radius=1), f, repeats=1, device="cuda")
    assert on_dev.backend == "triton" and host.backend == "numba"
    assert len(on_dev.transfer_s) == 1 and not host.transfer_s
    assert np.max(np.abs(on_dev.output - host.output)) < 1e-5
    assert on_dev.metrics["relmse"] == pytest.approx(host.metrics["relmse"], rel=1e-4)
    # a method without a device path runs on the host, and says so
    plain = harness.run_cell(get("noisy"), f, repeats=1, device="cuda")
    assert plain.device == "cpu" and not plain.transfer_s
    record = harness.cell_record(on_dev, [f], {"color"})
    assert {"device", "device_name", "backend", "transfer_s"} <= set(record)


def test_sweep_identity_names_a_gpu_device_only(monkeypatch):
    cfg = sweep.SweepConfig(methods=["jbf", "noisy"], scenes=["cornell"], spp=[4], res=16)
    scene = cfg.scene("cornell")
    cpu = sweep.cell_identity(cfg, scene, 4, "jbf", "fp")
    assert "device" not in cpu          # CPU cells keep their earlier identity
    cfg.device = "cuda"
    monkeypatch.setattr(sweep, "device_name", lambda d: "Some GPU")
    gpu = sweep.cell_identity(cfg, scene, 4, "jbf", "fp")
    assert gpu["device"] == "cuda" and gpu["device_name"] == "Some GPU"
    assert "device" not in sweep.cell_identity(cfg, scene, 4, "noisy", "fp")


def test_bench_gpu_dry_run_on_cpu_tensors():
    from dbench.speed import gpu
    r = gpu.bench_gpu(height=8, width=12, device="cpu", repeats=1, host_repeats=1,
                      methods_=["nca", "oidn", "noisy"], hostile_size=(8, 12), log=lambda s: None,
                      transient_renders=(("cornell-transient", 8, 1.2), ("no-such-scene", 8, 1)))
    rows = {x["method"]: x for x in r["rows"]}
    assert rows["nca"]["device_path"] and rows["nca"]["max_rel_diff"] < 1e-4
    assert rows["oidn"]["hostile_nonfinite"] == 0
    assert rows["oidn"]["backend"] == "oidn-cpu"  # CPU tensors: OIDN's CPU device ran
    assert not rows["noisy"]["device_path"] and "error" not in rows["noisy"]
    assert [q["quality"] for q in r["oidn_qualities"]] == ["high", "balanced", "fast"]
    assert "| nca |" in gpu.markdown(r)
    # the statistics cost of a render at the frame's size, on this process's variant
    render = r["render"]
    assert "error" not in render, render
    assert render["res"] == "12x8" and render["spp"] == 64
    assert render["ratio_stats_vs_plain"] > 0 and render["target_ratio"] == gpu.RENDER_TARGET
    # and of the transient per-bin statistics; a scene that fails is its row's error
    ok, bad = r["transient_render"]
    assert "error" not in ok, ok
    assert ok["res"] == 8 and ok["bins"] == 100 and ok["target_ratio"] == 1.2
    assert ok["ratio_stats_vs_plain"] > 0 and ok["ratio_stats_nocache_vs_plain"] > 0
    assert ok["first_rounds"] == 1 and ok["ratio_first_stats_vs_plain"] > 0  # a fresh process
    assert bad["scene"] == "no-such-scene" and "error" in bad
    text = gpu.markdown(r)
    assert "Transient per-bin statistics, cornell-transient 8² × 100 bins" in text
    assert "as the first call of a fresh process" in text
    assert "no-such-scene 8²: failed" in text


def test_bench_method_names_its_device_route():
    from dbench.speed import timing as speed
    from dbench.speed.gpu import bench_method_device
    r = bench_method_device("nca", 8, 12, 1, 16, {}, "cpu")
    assert r["backend"] == "torch" and r["device"] == "cpu" and r["oidn_time_s"] > 0
    assert "nca on cpu" in speed.format_result(r)
    with pytest.raises(DbenchInputError, match="no device path"):
        bench_method_device("jbf", 8, 12, 1, 16, {"mode": "illumination"}, "cpu")


@pytest.mark.parametrize("name", __import__("dbench.stress.device",
                                            fromlist=["device_methods"]).device_methods())
def test_no_device_path_converts_to_numpy_inside_a_call(name, monkeypatch):
    """Every method with a device path, called twice (a temporal method's second call uses its
    history), with every way out to NumPy or the host refused during the calls."""
    from dbench.stress import device as stress_device
    from dbench.speed.gpu import synthetic_frame
    frame = synthetic_frame(8, 12)
    m = get(name, **stress_device.DEVICE_FORM_PARAMS.get(name, {}))
    data = dev.upload(frame, "cpu", m.wants(harness._buffers(frame)))
    m.reset()

    # a few scalars read back (a synchronisation) are allowed; image data is not
    with host_conversions_refused(monkeypatch, ("numpy", "__array__"), small_tolist=8,
                                  what=f"{name}: a NumPy conversion inside the device call"):
        outs = [m.denoise_device(data) for _ in range(2)]
    assert all(isinstance(o, torch.Tensor) and o.shape == (8, 12, 3) for o in outs)
