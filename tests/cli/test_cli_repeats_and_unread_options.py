"""A repeated item of a comma list and an option the command (or benchmark, or combination of
options) does not read are refused in one line, exit 2, before anything renders or is timed
(README.md, "Usage"): ``--method jbf,jbf`` ran jbf once, ``export --spp 4,4`` promised 17 files
and wrote 10, ``bench jbf --bins 5`` and ``bench render --width 8`` ignored them, ``--cache X
--no-cache`` ignored ``--cache``, ``sweep --executor ray --workers 7`` ignored ``--workers``.

Every path that would render, time or sweep is replaced by a stand-in that fails the test, so
a check that lets an argument through never starts the work here."""
from __future__ import annotations

import pytest
from cli_args import refused  # tests/cli_args.py

from dbench import cli


@pytest.fixture
def no_work(monkeypatch, tmp_path):
    """Rendering, running a scene, sweeping and every benchmark fail loudly."""
    from dbench import datasets
    from dbench.cli import run as cli_run
    from dbench.run import sweep
    from dbench.speed import files, gpu, kernels, timing, transient_render, video_metrics
    from dbench.stress import runner

    def worked(*a, **k):
        raise AssertionError("the command went past its checks")

    for module, name in [(datasets, "load"), (cli_run, "run_scene"), (sweep, "run_sweep"),
                         (timing, "bench_render"), (timing, "bench_metrics"),
                         (timing, "bench_method"), (files, "bench_scene_file"),
                         (files, "bench_plugin_discovery"), (kernels, "precompile"),
                         (gpu, "bench_gpu"), (gpu, "bench_method_device"),
                         (transient_render, "bench_render_transient"),
                         (video_metrics, "bench_video_metrics"), (runner, "run_all")]:
        monkeypatch.setattr(module, name, worked)
    return tmp_path


@pytest.mark.parametrize("argv, words", [
    (["run", "--method", "jbf,jbf", "--scene", "cornell"], ["--method", "'jbf' is given twice"]),
    (["run", "--method", "statistical-gate,statistical+gate", "--scene", "cornell"],
     ["--method", "'statistical-gate' and 'statistical+gate' name the same item"]),
    (["run", "--method", "noisy,jbf,noisy", "--scene", "cornell"], ["'noisy' is given twice"]),
    (["sweep", "--spp", "4,4", "--methods", "jbf", "--scenes", "cornell"],
     ["--spp", "'4' is given twice", "'4,4'"]),
    (["sweep", "--spp", "4,16,4e0", "--methods", "jbf", "--scenes", "cornell"],
     ["--spp", "'4' and '4e0' name the same item"]),
    (["sweep", "--methods", "jbf,oidn,jbf", "--scenes", "cornell"], ["--methods", "'jbf'"]),
    (["sweep", "--methods", "jbf", "--scenes", "cornell,cornell"], ["--scenes", "'cornell'"]),
    (["export", "cornell", "--out", "OUT", "--spp", "4,4"], ["--spp", "'4' is given twice"]),
    (["render", "--scene", "cornell,caustic,cornell"], ["--scene", "'cornell'"]),
    (["stress", "--methods", "jbf,jbf"], ["--methods", "'jbf'"]),
])
def test_a_repeated_item_of_a_comma_list_is_refused(no_work, capsys, argv, words):
    out = no_work / "out"
    argv = [str(out) if a == "OUT" else a for a in argv]
    refused(capsys, [*argv, "--out", str(out)] if argv[0] in ("run", "sweep", "stress")
            else argv, *words)
    assert not out.exists()


@pytest.mark.parametrize("what, extra, words", [
    ("render", ["--device", "bogus"], ["device", "'bogus'", "'cpu'"]),
    ("kernels", ["--device", "bogus"], ["--device", "bench kernels does not read it"]),
    ("kernels", ["--device", "cpu"], ["--device", "bench kernels does not read it"]),
    ("metrics", ["--device", "cuda"], ["--device", "bench metrics does not read it"]),
    ("video-metrics", ["--device", "cpu"], ["--device", "bench video-metrics"]),
    ("jbf", ["--bins", "5"], ["--bins", "bench jbf (a method's benchmark) does not read it"]),
    ("jbf", ["--arch", "90"], ["--arch", "bench jbf"]),
    ("jbf", ["--jobs", "2"], ["--jobs", "bench jbf"]),
    ("jbf", ["--device", "bogus"], ["device", "'bogus'"]),
    ("metrics", ["--spp", "4"], ["--spp", "bench metrics does not read it", "--width"]),
    ("render", ["--width", "32"], ["--width", "bench render does not read it", "--res"]),
    ("render", ["--height", "32"], ["--height", "bench render"]),
    ("render", ["--arch", "90"], ["--arch", "bench render"]),
    ("scene-file", ["--bins", "5"], ["--bins", "bench scene-file"]),
    ("plugins", ["--res", "8"], ["--res", "bench plugins does not read it"]),
    ("plugins", ["--device", "cpu"], ["--device", "bench plugins"]),
    ("kernels", ["--res", "8"], ["--res", "bench kernels"]),
    ("kernels", ["--repeats", "2"], ["--repeats", "bench kernels"]),
    ("gpu", ["--spp", "4"], ["--spp", "bench gpu does not read it"]),
    ("gpu", ["--arch", "90"], ["--arch", "bench gpu"]),
    ("gpu", ["--device", "cpu", "--jobs", "2"], ["--jobs", "only on cuda"]),
    ("jbf", ["--res", "16", "--width", "32", "--height", "8"],
     ["--res 16", "--width/--height", "give --res or --width/--height"]),
    ("metrics", ["--res", "16", "--height", "8"], ["--res 16"]),
    ("bogus-method", ["--bins", "5"], ["bogus-method"]),  # the name first, with the choices
])
def test_bench_refuses_an_option_its_benchmark_does_not_read(no_work, capsys, what, extra,
                                                             words):
    refused(capsys, ["bench", what, *extra], *words)


def test_bench_device_cuda_is_refused_as_run_refuses_it_without_a_gpu(no_work, capsys):
    from dbench.device import cuda_usable

    if cuda_usable():
        pytest.skip("checks the refusal on a machine without a GPU")
    refused(capsys, ["bench", "jbf", "--device", "cuda"], "no usable CUDA GPU")
    refused(capsys, ["bench", "render", "--device", "cuda"], "no usable CUDA GPU")


def test_bench_options_that_apply_reach_the_benchmark(no_work, capsys, monkeypatch):
    """What each benchmark reads goes through: the sizes of a method's benchmark, --width
    alone, the repeats of bench plugins (its 3 rounds at least are gone: --repeats is read)."""
    from dbench.speed import files, timing

    seen = {}
    monkeypatch.setattr(timing, "bench_method",
                        lambda name, **k: seen.setdefault("method", k) and {})
    monkeypatch.setattr(timing, "format_result", lambda r: "")
    monkeypatch.setattr(files, "bench_plugin_discovery",
                        lambda repeats: seen.setdefault("plugins", repeats) and {})
    monkeypatch.setattr(files, "format_result", lambda r: "")
    assert cli.main(["bench", "jbf", "--width", "32", "--device", "cpu", "--repeats", "2"]) == 0
    assert (seen["method"]["width"], seen["method"]["height"]) == (32, 720)
    assert seen["method"]["repeats"] == 2
    assert cli.main(["bench", "plugins", "--repeats", "1"]) == 0 and seen["plugins"] == 1


def test_cache_with_no_cache_is_refused(no_work, capsys):
    cache = no_work / "cache"
    for argv in (["run", "--method", "jbf", "--scene", "cornell", "--out",
                  str(no_work / "out")],
                 ["render", "--scene", "cornell"],
                 ["export", "cornell", "--out", str(no_work / "out")],
                 ["sweep", "--methods", "jbf", "--scenes", "cornell", "--out",
                  str(no_work / "out")]):
        refused(capsys, [*argv, "--cache", str(cache), "--no-cache"], "--cache", "--no-cache")
    assert not cache.exists() and not (no_work / "out").exists()


def test_sweep_workers_with_the_ray_executor_is_refused(no_work, capsys):
    refused(capsys, ["sweep", "--methods", "jbf", "--scenes", "cornell", "--spp", "4",
                     "--executor", "ray", "--workers", "7", "--out", str(no_work / "out")],
            "--workers 7", "ray")
    assert not (no_work / "out").exists()
