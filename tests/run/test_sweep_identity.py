"""Sweep integrity: a cell is reused only when its whole
identity matches; other parameters make another labelled series; a changed default, code or
reference is refused (exit 2) unless --rerun; refused sweeps write nothing; temporary and
malformed files are never read as cells."""
import json
from pathlib import Path

import pytest
from cli_args import with_options  # tests/cli_args.py

from dbench import cli
from dbench.run import identity, sweep
from dbench.errors import DbenchInputError


def test_labels_name_the_parameters_that_differ_from_the_defaults():
    assert identity.label("jbf") == "jbf"
    assert identity.label("jbf", {"radius": 3}) == "jbf[radius=3]"
    default_radius = identity.resolved_params("jbf")["radius"]
    assert identity.label("jbf", {"radius": default_radius}) == "jbf"
    # an integer where the default is a float is that float: the same identity, not a cell
    # refused as changed (beta's default is 10.0)
    assert json.dumps(identity.resolved_params("jbf", {"beta": 10}), sort_keys=True) == \
        json.dumps(identity.resolved_params("jbf"), sort_keys=True)  # (10 == 10.0 in Python)
    assert identity.label("jbf", {"beta": 10}) == "jbf"
    assert identity.file_stem("jbf[radius=3]") == "jbf[radius=3]"
    odd = identity.file_stem("nca[weights=/tmp/x y.onnx]")
    assert "/" not in odd and odd.startswith("nca@")


def test_method_version_changes_with_its_code_and_is_stable():
    from dbench import registry
    cls = registry.method_class("jbf")
    assert identity.method_version(cls) == identity.method_version(cls)
    assert identity.method_version(cls) != identity.method_version(registry.method_class("oidn"))


def test_method_version_covers_the_code_a_method_uses():
    """Every function, class or module of ``dbench.methods`` that a method's modules hold (their
    own code and what they import: shared kernels, another method's steps) lives in a file
    that the method's version hashes."""
    import inspect
    import sys

    from dbench import methods, registry
    root = Path(methods.__file__).resolve().parent
    for name in ("jbf", "statistical", "jbf-bins", "svgf", "bmfr", "accumulate"):
        cls = registry.method_class(name)
        files = set(identity.method_files(cls))
        package = cls.__module__
        modules = [m for n, m in list(sys.modules.items())
                   if n == package or n.startswith(package + ".")]
        assert modules
        for module in modules:
            for value in vars(module).values():
                if inspect.ismodule(value):
                    owner = value
                elif inspect.isfunction(value) or inspect.isclass(value):
                    owner = inspect.getmodule(value)
                else:
                    continue
                path = getattr(owner, "__file__", None)
                if path and root in Path(path).resolve().parents:
                    assert Path(path).resolve() in files, (name, module.__name__, path)


def test_gpu_code_is_part_of_a_device_cell_only(tmp_path):
    """A CPU cell's method version leaves out the files that only a device runs (the Triton
    kernels, the device paths): editing a GPU kernel changes no CPU number. A device cell's
    version counts them. A plugin's files always count."""
    from dbench import methods, registry
    root = Path(methods.__file__).resolve().parent
    assert identity.device_only(root / "kernels" / "gpu" / "svgf.py")
    assert identity.device_only(root / "svgf" / "device.py")
    assert identity.device_only(root / "statistical" / "transient_device.py")
    assert not identity.device_only(root / "svgf" / "__init__.py")
    assert not identity.device_only(root / "kernels" / "bilateral" / "numba2d.py")
    (tmp_path / "device.py").write_text("x = 1\n")
    assert not identity.device_only(tmp_path / "device.py")
    for name in ("svgf", "statistical", "bmfr", "oidn"):
        cls = registry.method_class(name)
        files = identity.method_files(cls)
        gpu = [f for f in files if identity.device_only(f)]
        assert gpu and len(gpu) < len(files), name
        assert identity.method_version(cls) != identity.method_version(cls, "cuda"), name
    noisy = registry.method_class("noisy")
    assert identity.method_version(noisy) == identity.method_version(noisy, "cuda")


def test_host_modules_do_not_import_device_code_at_load():
    """What a host call runs is in the CPU version: no host module of a method imports a
    device-only file at module level (device paths are imported inside denoise_device)."""
    import ast

    from dbench import registry
    for name in registry.available():
        for f in identity.method_files(registry.method_class(name)):
            if f.suffix != ".py" or identity.device_only(f):
                continue
            tree = ast.parse(f.read_text(encoding="utf-8"))
            for node in tree.body:
                if isinstance(node, ast.ImportFrom) and node.level:
                    base = f.parent
                    for _ in range(node.level - 1):
                        base = base.parent
                    target = base.joinpath(*(node.module or "").split("."))
                    for cand in (target.with_suffix(".py"), target / "__init__.py"):
                        assert not (cand.exists() and identity.device_only(cand)), (f, cand)


def test_code_version_ignores_documentation_but_not_code(tmp_path):
    """A docstring, a comment or reformatting keeps a method's code version (docs can be edited
    without recomputing published cells); a changed constant or statement changes it."""
    base = 'def f(x):\n    """Doc."""\n    return x * 2  # why\n'
    same = ('def f(x):\n    """Other words, docs/methods/jbf.md §2."""\n\n'
            '    return (x *\n            2)\n')
    other = 'def f(x):\n    """Doc."""\n    return x * 3\n'
    texts = {}
    for name, text in (("base", base), ("same", same), ("other", other)):
        f = tmp_path / name / "m.py"
        f.parent.mkdir()
        f.write_text(text)
        texts[name] = identity._hash_files([f])
    assert texts["base"] == texts["same"] != texts["other"]
    onnx = tmp_path / "w.onnx"
    onnx.write_bytes(b"\x00\x01")
    assert identity.code_text(onnx) == b"\x00\x01"


def _write(path: Path, obj) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(obj if isinstance(obj, str) else json.dumps(obj))


def test_temporary_and_malformed_cell_files_are_not_cells(tmp_path):
    ok = {"status": "ok", "scene": "cornell", "method": "noisy", "spp": 4, "rmse": 0.1}
    _write(tmp_path / "cells/cornell/00004spp/noisy.json", ok)
    _write(tmp_path / "cells/cornell/00004spp/.jbf.json.abc123.tmp.json", ok)
    _write(tmp_path / "cells/cornell/00004spp/list.json", [1, 2])
    _write(tmp_path / "cells/cornell/00004spp/abc.json", {**ok, "method": "jbf", "rmse": "abc"})
    _write(tmp_path / "cells/cornell/00004spp/torn.json", '{"status": "o')
    cells, problems = sweep.load_cells_checked(tmp_path)
    assert [c["method"] for c in cells] == ["noisy"]
    assert len(problems) == 3 and any("rmse is 'abc'" in p for p in problems)


def test_bad_sweep_arguments_exit_2_and_write_nothing(tmp_path, capsys):
    out = tmp_path / "S"
    for bad in (["--res", "0"], ["--spp", "4,abc"], ["--spp", "0"], ["--seeds", "0"],
                ["--res", "100000"], ["--param", "jbf.radius=" + "9" * 2000]):
        rc = cli.main(with_options(["sweep", "--methods", "noisy,jbf", "--scenes", "cornell",
                                    "--spp", "4", "--res", "16", "--out", str(out), "--quiet"],
                                   *bad))
        err = capsys.readouterr().err
        assert rc == 2 and err.startswith("dbench: ") and "Traceback" not in err, bad
        assert not out.exists(), bad
    (tmp_path / "file").write_text("x")
    rc = cli.main(["sweep", "--methods", "noisy", "--scenes", "cornell", "--spp", "4",
                   "--res", "16", "--out", str(tmp_path / "file"), "--quiet"])
    assert rc == 2 and "not a folder" in capsys.readouterr().err


def test_report_refuses_missing_folders_without_creating_them(tmp_path, capsys):
    rc = cli.main(["report", "--results", str(tmp_path / "none")])
    assert rc == 2 and not (tmp_path / "none").exists()
    (tmp_path / "r").mkdir()
    rc = cli.main(["report", "--results", str(tmp_path / "r"), "--sweep", str(tmp_path / "s")])
    assert rc == 2 and "sweep" in capsys.readouterr().err


def _sweep(capsys, out, *extra):
    """``dbench sweep`` in this process (a subprocess per call cost seconds of start-up each;
    the identities it checks are read back from the folder either way): (exit code, stderr)."""
    code = cli.main(["sweep", "--methods", "noisy,jbf", "--scenes", "cornell", "--res", "16",
                     "--ref-spp", "64", "--repeats", "1", "--out", str(out), "--quiet", *extra])
    return code, capsys.readouterr().err


@pytest.mark.mitsuba
def test_changed_parameters_make_a_second_labelled_series(renderer, tmp_path, monkeypatch,
                                                          capsys):
    out = tmp_path / "S"
    monkeypatch.setenv("DBENCH_CACHE", str(tmp_path / "cache"))
    code, err = _sweep(capsys, out, "--spp", "4")
    assert code == 0, err
    code, err = _sweep(capsys, out, "--spp", "4,16", "--param", "jbf.radius=3")
    assert code == 0, err
    cells = sweep.load_cells(out)
    series = {(c["method"], c["spp"]): c for c in cells}
    assert set(series) == {("noisy", 4), ("noisy", 16), ("jbf", 4), ("jbf[radius=3]", 4),
                           ("jbf[radius=3]", 16)}
    default_radius = identity.resolved_params("jbf")["radius"]
    assert series[("jbf", 4)]["params"]["radius"] == default_radius
    assert all(series[("jbf[radius=3]", s)]["params"]["radius"] == 3 for s in (4, 16))
    stored = sweep.read_cell(out / "sweep.json")["config"]
    assert {"jbf", "jbf[radius=3]"} <= set(stored["labels"])
    # another reference spp under the same labels is refused before rendering, with exit 2
    third, _ = _sweep(capsys, out, "--spp", "4")
    assert third == 0
    monkeypatch.setenv("DBENCH_REF_SPP", "128")
    code = cli.main(["sweep", "--methods", "noisy", "--scenes", "cornell", "--res", "16",
                     "--repeats", "1", "--spp", "4", "--out", str(out), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and "ref_spp" in err
    assert "Traceback" not in err


@pytest.mark.mitsuba
def test_a_changed_default_is_refused_and_rerun_recomputes(renderer, tmp_path, monkeypatch):
    from dbench import registry
    cfg = dict(methods=["noisy", "jbf"], scenes=["cornell"], spp=[4], res=12, ref_spp=16,
               repeats=1, cache=str(tmp_path / "cache"))
    out = tmp_path / "S"
    sweep.run_sweep(sweep.SweepConfig(**cfg), out, progress=False)
    cls = registry.method_class("jbf")
    monkeypatch.setattr(cls, "defaults", {**cls.defaults, "radius": 2})
    with pytest.raises(DbenchInputError, match="params.radius"):
        sweep.run_sweep(sweep.SweepConfig(**cfg), out, progress=False)
    counts = sweep.run_sweep(sweep.SweepConfig(**cfg, rerun=True), out, progress=False)
    assert counts["computed"] == 1 and counts["finished_before"] == 1
    cell = sweep.read_cell(sweep.cell_path(out, "cornell", 4, "jbf"))
    assert cell["params"]["radius"] == 2


@pytest.mark.mitsuba
def test_sweep_with_three_seeds_shares_one_reference(renderer, tmp_path):
    out = tmp_path / "S"
    cfg = sweep.SweepConfig(methods=["noisy", "jbf"], scenes=["cornell"], spp=[4], res=16,
                            ref_spp=64, repeats=1, seeds=3, cache=str(tmp_path / "cache"))
    sweep.run_sweep(cfg, out, progress=False)
    refs = list((tmp_path / "cache" / "reference").glob("*/meta.json"))
    assert len(refs) == 1
    for c in sweep.load_cells(out):
        assert c["n_seeds"] == 3 and c["seeds"] == [0, 1, 2] and c["ref_spp"] == 64
        assert c["rmse_ci"] > 0 and c["rmse_surface_ci"] > 0 and c["relmse_ci"] > 0
        assert len(c["per_seed"]) == 3 and 0 < c["top1_share"] <= 1


def test_a_folder_cell_names_the_transform_its_statistics_were_gathered_with(tmp_path):
    """A folder's statistics are read as they are: its cells' identity holds their transform
    and λ per spp (a variance image: identity), not the sweep's default for the kind."""
    import numpy as np

    from dbench.data import Frame, SampleStats
    from dbench.datasets.folders.export import export_frame
    from dbench.datasets.scenes import catalogue
    from exr_files import write_rgb  # tests/exr_files.py

    rng = np.random.default_rng(3)
    img = rng.random((8, 8, 3)).astype(np.float32)
    write_rgb(tmp_path / "v_ref.hdr.exr", img)
    write_rgb(tmp_path / "v_0004.hdr.exr", img)
    write_rgb(tmp_path / "v_0004.var.exr", np.full((8, 8, 3), 0.01, np.float32))
    stats = SampleStats(n=np.full((8, 8, 3), 16.0), mean=img.astype(np.float64),
                        var_mean=np.full((8, 8, 3), 1e-3), m3=np.zeros((8, 8, 3)),
                        transform="yeo-johnson", lam=0.25)
    export_frame(Frame(color=img, stats=stats, meta={}), tmp_path, "v", 16,
                 write_reference=False)
    scene = catalogue.get(str(tmp_path))
    assert scene.info.stats_settings == {4: ("identity", 0.5), 16: ("yeo-johnson", 0.25)}
    cfg = sweep.SweepConfig(methods=["noisy"], scenes=[str(tmp_path)], spp=[4, 16])
    got = {spp: sweep.cell_identity(cfg, scene, spp, "noisy", "fp") for spp in (4, 16)}
    assert (got[4]["transform"], got[4]["lam"]) == ("identity", 0.5)
    assert (got[16]["transform"], got[16]["lam"]) == ("yeo-johnson", 0.25)
    # a rendered scene keeps the kind's default
    cornell = sweep.cell_identity(cfg, catalogue.get("cornell"), 4, "noisy", "fp")
    assert (cornell["transform"], cornell["lam"]) == ("box-cox", 0.5)


@pytest.mark.parametrize("name", ["judge.py", "scoring.py", "sequence_run.py"])
def test_the_judge_version_covers_every_file_that_makes_a_cells_numbers(monkeypatch, name):
    """Which pixels are judged (run/scoring.py) and a sequence's protocol (run/sequence_run.py:
    the frames averaged and timed, t_rmse) change numbers as the metrics do; a resumed sweep
    kept cells made by their older code."""
    from dbench.run import identity
    before, real = identity.judge_version.__wrapped__(), identity.code_text
    monkeypatch.setattr(identity, "code_text",
                        lambda p: real(p) + (b"changed = 1\n" if p.name == name else b""))
    assert identity.judge_version.__wrapped__() != before
