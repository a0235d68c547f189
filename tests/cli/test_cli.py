"""The command line: run, list, unknown names, parameters."""
import json

import pandas as pd
import pytest

from dbench.cli import main, parse_params
from dbench.errors import DbenchInputError


def test_unknown_method_and_scene_exit_2_and_list_names(capsys):
    assert main(["run", "--method", "nope", "--scene", "cornell"]) == 2
    assert "available methods" in capsys.readouterr().err
    assert main(["run", "--method", "noisy", "--scene", "nope"]) == 2
    assert "cornell" in capsys.readouterr().err


def test_list_prints_scenes_and_methods(capsys):
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert "cornell" in out and "oidn" in out and "needs=" in out


def test_params_route_to_methods():
    p = parse_params(["quality=fast", "oidn.features=albedo"], ["noisy", "oidn"])
    assert p["oidn"] == {"quality": "fast", "features": "albedo"} and p["noisy"] == {}
    with pytest.raises(DbenchInputError, match="no method"):
        parse_params(["radiusx=3"], ["noisy"])
    with pytest.raises(DbenchInputError, match="has no parameter"):
        parse_params(["oidn.bogus=1"], ["oidn"])


@pytest.mark.mitsuba
def test_run_writes_metrics_report_images(renderer, tmp_path, capsys):
    out = tmp_path / "run"
    code = main(["run", "--method", "oidn", "--scene", "cornell", "--spp", "4", "--res", "16",
                 "--ref-spp", "32", "--repeats", "1", "--out", str(out), "--quiet",
                 "--cache", str(tmp_path / "cache")])
    assert code == 0
    table = pd.read_csv(out / "metrics.csv")
    for col in ("scene", "method", "spp", "res", "rmse", "relmse", "smape", "psnr", "ssim",
                "flip", "time_s"):
        assert col in table.columns
    assert list(table.method) == ["noisy", "oidn"]
    assert (out / "report.md").read_text().startswith("# dbench run")
    assert (out / "comparison.png").stat().st_size > 1000
    assert (out / "images" / "oidn.exr").exists() and (out / "images" / "reference.exr").exists()
    assert not list(out.rglob(".*tmp*"))


@pytest.mark.mitsuba
def test_run_on_a_sequence_scene_writes_per_frame_results(renderer, tmp_path):
    out = tmp_path / "seq"
    code = main(["run", "--method", "svgf,accumulate", "--scene", "orbit", "--spp", "1",
                 "--res", "12", "--frames", "10", "--ref-spp", "8", "--out", str(out),
                 "--quiet", "--cache", str(tmp_path / "cache")])
    assert code == 0
    table = pd.read_csv(out / "metrics.csv")
    assert list(table.method) == ["noisy", "svgf", "accumulate"]
    assert {"t_rmse", "tpsnr"} <= set(table.columns)
    per_frame = pd.read_csv(out / "per_frame_svgf.csv")
    assert len(per_frame) == 10 and per_frame.frame.tolist() == list(range(10))
    report = (out / "report.md").read_text()
    assert "Sequence: every frame is denoised once" in report
    assert "frame ×10" in report  # cache parts summarised, not listed 10 times
    # the settings give the reference RMSE the cells give: over the judged frames 8-9
    settings = json.loads((out / "run.json").read_text())["settings"]
    stated = float(str(settings["reference RMSE (estimated)"]).split()[0])
    assert stated == pytest.approx(table.ref_rmse[0], rel=1e-6)
    for name in ("comparison.png", "error_per_frame.png", "images/svgf.exr",
                 "images/reference.exr"):
        assert (out / name).stat().st_size > 500


@pytest.mark.mitsuba
def test_run_all_methods_skips_those_that_do_not_apply(renderer, tmp_path, capsys):
    from dbench import registry

    out = tmp_path / "all"
    code = main(["run", "--method", "all", "--scene", "textured", "--spp", "2", "--res", "12",
                 "--ref-spp", "8", "--repeats", "1", "--out", str(out),
                 "--cache", str(tmp_path / "cache")])
    assert code == 0
    table = pd.read_csv(out / "metrics.csv")
    steady = {m for m in registry.available() if "steady" in registry.method_class(m).kinds}
    assert set(table.method) == steady
    printed = capsys.readouterr().out
    # one line for every skipped method, grouped by the kind of reason
    skips = [ln for ln in printed.splitlines() if ln.startswith("skipped:")]
    assert len(skips) == 1 and "skipping" not in printed
    assert "svgf" in skips[0].split("(sequence only)")[0]
    assert "## Skipped" in (out / "report.md").read_text()


def test_bench_times_a_method_at_the_spp_and_parameters_given(tmp_path, capsys):
    """``dbench bench METHOD``: the synthetic frame's statistics have --spp samples, so nca
    takes its step count for that spp; --param builds the method; the record says both."""
    import json

    from dbench.methods.nca import default_iterations

    out = tmp_path / "bench.jsonl"
    assert main(["bench", "nca", "--res", "24x16", "--spp", "4", "--repeats", "1",
                 "--out", str(out)]) == 0
    assert main(["bench", "nca", "--res", "24x16", "--param", "iterations=2", "--repeats", "1",
                 "--out", str(out)]) == 0
    first, second = [json.loads(line) for line in out.read_text().splitlines()]
    assert first["spp"] == 4 and first["width"] == 24 and first["height"] == 16
    assert first["fast_vs_reference"]["iterations"] == default_iterations(spp=4)
    assert second["spp"] == 16 and second["params"]["iterations"] == 2
    assert "4 spp" in capsys.readouterr().out
    for bad in (["render", "--param", "iterations=2"], ["nca", "--spp", "0"],
                ["nca", "--param", "bogus=1"]):
        assert main(["bench", *bad, "--res", "8"]) == 2
        err = capsys.readouterr().err
        assert err.startswith("dbench: ") and err.count("\n") == 1, err


def test_bench_frame_says_its_spp_to_the_method():
    """The timed method sees a frame of --spp samples as a rendered one: statistics of that
    count and meta["spp"] (which nca's step count and noise gate read), with its parameters."""
    from dbench.speed.timing import bench_method
    from dbench.denoiser import _REGISTRY, Denoiser, register
    from dbench.methods.kernels.hdr_input import frame_spp

    seen = []

    @register("test-bench-spp")
    class Probe(Denoiser):
        kinds = {"steady"}
        needs = {"color"}
        defaults = {"scale": 1.0}

        def denoise(self, data):
            seen.append((frame_spp(data), float(data.stats.n.min()), self.params["scale"]))
            return data.color * self.params["scale"]

    try:
        result = bench_method("test-bench-spp", height=8, width=12, repeats=1, spp=4,
                              params={"scale": 0.5})
    finally:
        _REGISTRY.pop("test-bench-spp", None)
    assert seen and set(seen) == {(4.0, 4.0, 0.5)}
    assert result["spp"] == 4 and result["params"]["scale"] == 0.5


def test_gate_share_is_paired_per_round_with_the_order_alternating():
    """The gate's share of its method's time: the two are timed in turn in each round, the order
    reversed every other round (ABBA), and the share is the median of the per-round ratios
    with its quartiles; ``dbench bench NAME+gate`` reports it so."""
    from dbench.speed.timing import bench_method, interleaved_times, paired_share

    calls = []
    times = interleaved_times([lambda: calls.append("a"), lambda: calls.append("b")], 4)
    assert calls == ["a", "b"] + ["a", "b", "b", "a", "a", "b", "b", "a"]  # warm-up, then ABBA
    assert [len(t) for t in times] == [4, 4]
    share = paired_share([1.2, 2.2, 1.1, 3.3, 1.15], [1.0, 2.0, 1.0, 3.0, 1.0])
    assert abs(share["median"] - 0.1) < 1e-12 and share["rounds"] == 5
    assert share["q25"] <= share["median"] <= share["q75"]
    result = bench_method("jbf+gate", height=8, width=12, repeats=1, spp=4)
    lo, hi = result["gate_overhead_quartiles"]
    assert lo <= result["gate_overhead"] <= hi and result["gate_overhead_rounds"] >= 5
