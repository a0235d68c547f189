"""Plugins: outside denoisers and scenes from files, modules, $DBENCH_PLUGINS and entry points.

Nothing is pip-installed: the entry-point tests put a ``*.dist-info`` folder (METADATA and
entry_points.txt) and the example package on a temporary path, which importlib.metadata finds.
Renders are tiny (8 px, 2 spp, reference 8 spp) and cached under the test's tmp path.
"""
from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from dbench import cli, plugins, registry
from dbench.run import identity

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "dbench-example-plugin"

MY_METHOD = '''
import numpy as np
from dbench.registry import Denoiser, register


@register("{name}")
class Half(Denoiser):
    """The input blended with its 2x2 mean: a stand-in for an outside denoiser."""
    kinds = {{"steady"}}
    needs = {{"color"}}
    defaults = {{"weight": 0.5}}

    def denoise(self, data):
        x = np.asarray(data.color, dtype=np.float64)
        y = 0.25 * (x + np.roll(x, 1, 0) + np.roll(x, 1, 1) + np.roll(np.roll(x, 1, 0), 1, 1))
        w = float(self.params["weight"])
        out = np.where(np.isfinite(y), (1 - w) * x + w * y, x)
        return out.astype(np.float32)
'''


def _method_file(folder: Path, name: str = "outside-half") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "my_method.py"
    path.write_text(MY_METHOD.format(name=name))
    return path


def _fake_install(site: Path, entry_points: str) -> Path:
    """The example package and a dist-info folder on ``site``: what pip would install."""
    site.mkdir(parents=True, exist_ok=True)
    shutil.copytree(EXAMPLE / "dbench_example_plugin", site / "dbench_example_plugin")
    info = site / "dbench_example_plugin-0.1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: dbench-example-plugin\n"
                                   "Version: 0.1.0\n")
    (info / "entry_points.txt").write_text(textwrap.dedent(entry_points))
    return site


EP_TEXT = """\
    [dbench.methods]
    box3 = dbench_example_plugin:Box3
    broken_one = no_such_module_for_dbench:Thing
    """


# ---------------------------------------------------------------------------------------------
# fast: no rendering


def test_plugin_option_is_taken_before_and_after_the_subcommand():
    rest, specs = cli.split_plugin_args(["--plugin", "a.py", "list", "--plugin=b", "--methods-only"])
    assert rest == ["list", "--methods-only"] and specs == ["a.py", "b"]
    assert cli.main(["list", "--plugin"]) == 2


def test_loading_twice_registers_once(isolated, tmp_path, monkeypatch):
    path = _method_file(tmp_path / "plug")
    first = plugins.load(str(path))
    monkeypatch.chdir(tmp_path)
    second = plugins.load("plug/my_method.py")  # another spelling of the same file
    third = plugins.load_all([str(path)])[0]
    assert first is second is third and first.ok and first.provides == ["outside-half"]
    assert registry.available().count("outside-half") == 1
    cls = registry.method_class("outside-half")
    assert cls.__module__ == plugins.module_name_for_file(path)
    assert plugins.requested() == [str(path.resolve())]
    plugins.worker_init(plugins.requested())  # what a worker does: nothing new here
    assert registry.method_class("outside-half") is cls
    # A method defined in a stand-alone file is versioned by that file alone.
    (tmp_path / "plug" / "unrelated.py").write_text("x = 1\n")
    h = hashlib.sha256(path.name.encode() + identity.code_text(path)).hexdigest()[:12]
    assert identity.method_version(cls) == h


def test_dbench_plugins_environment_variable(isolated, tmp_path, monkeypatch):
    path = _method_file(tmp_path / "env", name="env-half")
    monkeypatch.setenv(plugins.ENV_VAR, os.pathsep.join([str(path), "", str(path)]))
    plugins._STATE["discovered"] = False  # a fresh process
    assert "env-half" in registry.available()
    assert [p.origin for p in plugins.all_plugins() if "env-half" in p.provides] == [
        plugins.ENV_VAR]


def test_broken_file_plugin_exits_2_and_is_listed(isolated, tmp_path, capsys):
    bad = tmp_path / "bad_plugin.py"
    bad.write_text("import numpy as np\nraise RuntimeError('no GPU here')\n")
    assert cli.main(["--plugin", str(bad), "run", "--method", "noisy", "--scene", "cornell"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "bad_plugin.py" in err[0] and "RuntimeError: no GPU here" in err[0]
    assert cli.main(["list", "--plugin", str(bad)]) == 0
    out = capsys.readouterr().out
    assert "bad_plugin.py" in out and "BROKEN" in out and "no GPU here" in out
    assert "noisy" in registry.available() and registry.get("noisy") is not None


BAD_METHODS = '''
import numpy as np
from dbench.registry import Denoiser, register


class Base(Denoiser):
    kinds = {"steady"}
    needs = {"color"}


@register("bench-none")
class ReturnsNone(Base):
    def denoise(self, data):
        return None


@register("bench-raises")
class Raises(Base):
    def denoise(self, data):
        raise RuntimeError("no model\\nloaded")


@register("bench-writes")
class Writes(Base):
    def denoise(self, data):
        data.color.flags.writeable = True  # its copy owns its memory: NumPy allows this
        data.color[...] = 0
        return np.zeros(data.color.shape, np.float32)
'''


@pytest.mark.parametrize("name, said", [
    ("bench-none", "bench-none output: expected shape (8, 8, 3), got None"),
    ("bench-raises", "bench-raises failed: RuntimeError: no model loaded"),
    ("bench-writes", "bench-writes: modified its input buffer color")])
def test_bench_of_a_plugin_that_breaks_the_contract_fails_in_one_line(isolated, tmp_path, capsys,
                                                                      name, said):
    # dbench bench timed a method returning None (and published its Mpix/s), timed OIDN on the
    # frame a method had zeroed, and called a method's exception an internal error (exit 1)
    path = tmp_path / "bad_methods.py"
    path.write_text(BAD_METHODS)
    out = tmp_path / "bench.jsonl"
    rc = cli.main(["bench", name, "--plugin", str(path), "--res", "8", "--repeats", "1",
                   "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 4 and len(err) == 1 and err[0].startswith(f"dbench: bench {said}"), err
    assert not out.exists()


def test_a_plugin_method_that_cannot_be_built_is_refused_in_one_line(isolated, tmp_path,
                                                                       capsys):
    # its constructor's FileNotFoundError ended run, sweep, bench and stress as an "internal
    # error" of dbench (exit 1)
    path = tmp_path / "needs_weights.py"
    path.write_text("from dbench.registry import Denoiser, register\n\n\n"
                    "@register('needs-weights')\nclass NeedsWeights(Denoiser):\n"
                    "    def __init__(self, **params):\n"
                    "        super().__init__(**params)\n"
                    "        raise FileNotFoundError('weights.pt not found')\n")
    for argv in (["run", "--method", "needs-weights", "--scene", "cornell",
                  "--out", str(tmp_path / "run")],
                 ["bench", "needs-weights", "--res", "8", "--repeats", "1"]):
        assert cli.main([*argv, "--plugin", str(path)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert err == [f"dbench: method needs-weights ({path}) could not be built: "
                       "FileNotFoundError: weights.pt not found"], err
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("needs, said", [
    ('{"color", "bogus"}', "method 'late-needs' needs unknown buffers ['bogus']; valid: color"),
    ('{"color", "reference"}', "method 'late-needs' needs the reference")])
def test_needs_a_plugin_sets_when_it_is_built_are_checked_as_its_class_is(
        isolated, tmp_path, capsys, needs, said):
    # register() checks the class's needs; set in __init__, an unknown buffer skipped the
    # method on every scene ("needs ['bogus']") and "reference" would have been asked for
    path = tmp_path / "late_needs.py"
    path.write_text("from dbench.registry import Denoiser, register\n\n\n"
                    "@register('late-needs')\nclass LateNeeds(Denoiser):\n"
                    "    def __init__(self, **params):\n"
                    "        super().__init__(**params)\n"
                    f"        self.needs = {needs}\n\n"
                    "    def denoise(self, data):\n        return data.color\n")
    out = tmp_path / "run"
    assert cli.main(["run", "--method", "late-needs", "--scene", "cornell", "--res", "8",
                     "--spp", "2", "--plugin", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(
        f"dbench: method late-needs ({path}) could not be built: {said}"), err
    assert not out.exists()


def test_a_folder_given_as_a_plugin_is_refused_as_a_folder(isolated, tmp_path, capsys):
    # a package's folder was "no such file" though it is there
    (tmp_path / "mypkg").mkdir()
    (tmp_path / "mypkg" / "__init__.py").write_text("")
    assert cli.main(["run", "--method", "noisy", "--scene", "cornell",
                     "--plugin", str(tmp_path / "mypkg")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "IsADirectoryError" in err[0] and "is a folder" in err[0] \
        and f"--plugin mypkg with {tmp_path} on PYTHONPATH" in err[0], err


def test_a_plugin_that_registers_nothing_is_named_where_its_method_is_asked_for(
        isolated, tmp_path, capsys):
    # its class without @register loaded silently, and --method blur3 was only "unknown"
    path = tmp_path / "forgot.py"
    path.write_text("from dbench.registry import Denoiser\n\n\nclass Blur3(Denoiser):\n"
                    "    def denoise(self, data):\n        return data.color\n")
    assert cli.main(["run", "--method", "blur3", "--scene", "cornell",
                     "--plugin", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "unknown method 'blur3'" in err[0] and err[0].endswith(
        "plugin forgot.py loaded but registered no method (a Denoiser subclass needs "
        '@register("NAME"))'), err


def test_entry_points_found_in_process(isolated, tmp_path):
    site = _fake_install(tmp_path / "site", EP_TEXT)
    sys.path.insert(0, str(site))
    plugins.discover_entry_points()
    again = plugins.discover_entry_points()  # idempotent
    assert registry.available().count("box3") == 1
    by_name = {p.name: p for p in again}
    assert by_name["box3"].ok and by_name["box3"].provides == ["box3"]
    assert by_name["box3"].origin == "entry point (dbench-example-plugin)"
    assert not by_name["broken_one"].ok and "no_such_module_for_dbench" in by_name[
        "broken_one"].error
    with pytest.raises(plugins.PluginError, match="broken_one.*No module named"):
        registry.method_class("broken_one")
    with pytest.raises(registry.UnknownNameError):
        registry.method_class("never-heard-of")
    # The example package is versioned by its package folder.
    assert identity.method_version(registry.method_class("box3"))


def test_scene_entry_point_objects(isolated):
    from dbench.datasets.scenes import catalogue as scenes

    def build(mi, res):
        """A one-line description from the docstring."""
        return scenes.cornell(mi, res)

    plugins._register_scene_object("tiny-room", build)
    plugins._register_scene_object("tiny-room", build)  # twice: once
    sc = scenes.get("tiny-room")
    assert sc.kind == "steady" and sc.description.startswith("A one-line")
    made = scenes.Scene(name="tiny-room-2", kind="steady", description="x", build=build)
    plugins._register_scene_object("ignored", lambda: made)
    assert scenes.get("tiny-room-2") is made
    with pytest.raises(TypeError):
        plugins._register_scene_object("nope", lambda: 3)


def test_worker_start_loads_the_parent_plugins_in_a_fresh_process(isolated, tmp_path):
    """A spawned pool worker (nothing inherited) builds and versions the plugin method."""
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    from dbench.run import sweep

    path = _method_file(tmp_path / "w", name="worker-half")
    plugins.load(str(path))
    cls = registry.method_class("worker-half")
    env = os.environ.pop(plugins.ENV_VAR, None)
    try:
        with ProcessPoolExecutor(1, mp_context=mp.get_context("spawn"),
                                 initializer=sweep._worker_start,
                                 initargs=(plugins.requested(),)) as pool:
            names = pool.submit(registry.available).result(timeout=120)
            version = pool.submit(identity.method_version, cls).result(timeout=60)
    finally:
        if env is not None:
            os.environ[plugins.ENV_VAR] = env
    assert "worker-half" in names and version == identity.method_version(cls)


# ---------------------------------------------------------------------------------------------
# tiny renders


@pytest.mark.mitsuba
def test_file_plugin_through_run_sweep_and_report(renderer, isolated, tmp_path, monkeypatch,
                                                  capsys):
    monkeypatch.setenv("DBENCH_CACHE", str(tmp_path / "cache"))
    path = _method_file(tmp_path / "plug")
    tiny = ["--res", "8", "--ref-spp", "8", "--repeats", "1", "--quiet"]
    code = cli.main(["--plugin", str(path), "run", "--method", "outside-half", "--scene",
                     "cornell", "--spp", "2", "--out", str(tmp_path / "run"), *tiny])
    assert code == 0, capsys.readouterr().err
    assert "outside-half" in (tmp_path / "run" / "metrics.csv").read_text()

    # The sweep runs in its own process: its pool workers are forked from it and must load the
    # plugin themselves (and a process that already ran FLIP's OpenMP must not fork).
    results = tmp_path / "results"
    env = {**os.environ, "DBENCH_CACHE": str(tmp_path / "cache")}
    env.pop(plugins.ENV_VAR, None)
    swept = subprocess.run(
        [sys.executable, "-m", "dbench.cli", "sweep", "--plugin", str(path), "--methods",
         "outside-half", "--scenes", "cornell", "--spp", "2,4", "--workers", "2", "--out",
         str(results / "sweep"), *tiny], env=env, capture_output=True, text=True, timeout=300)
    assert swept.returncode == 0, swept.stderr
    from dbench.run import sweep

    cells = [c for c in sweep.load_cells(results / "sweep") if c["method"] == "outside-half"]
    assert len(cells) == 2 and all(c["status"] == "ok" for c in cells)
    version = identity.method_version(registry.method_class("outside-half"))
    assert {c["identity"]["method_version"] for c in cells} == {version}
    code = cli.main(["report", "--results", str(results), "--plugin", str(path)])
    assert code == 0, capsys.readouterr().err
    assert "outside-half" in (results / "README.md").read_text()


@pytest.mark.mitsuba
def test_entry_point_plugin_listed_and_runs_in_a_fresh_process(renderer, tmp_path):
    site = _fake_install(tmp_path / "site", EP_TEXT)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(site)] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]),
        "DBENCH_CACHE": str(tmp_path / "cache")}
    env.pop(plugins.ENV_VAR, None)

    def dbench(*args):
        return subprocess.run([sys.executable, "-m", "dbench.cli", *args], env=env,
                              capture_output=True, text=True, timeout=300, cwd=tmp_path)

    listed = dbench("list")
    assert listed.returncode == 0, listed.stderr
    lines = {ln.split()[0]: ln for ln in listed.stdout.splitlines() if ln.strip()}
    assert "entry point (dbench-example-plugin)" in lines["box3"]
    assert "BROKEN" in lines["broken_one"] and "No module named" in lines["broken_one"]
    ran = dbench("run", "--method", "box3", "--scene", "cornell", "--spp", "2", "--res", "8",
                 "--ref-spp", "8", "--repeats", "1", "--quiet", "--out", str(tmp_path / "run"))
    assert ran.returncode == 0, ran.stderr
    assert "box3" in (tmp_path / "run" / "metrics.csv").read_text()
    asked = dbench("run", "--method", "broken_one", "--scene", "cornell")
    err = asked.stderr.strip().splitlines()
    assert asked.returncode == 2 and len(err) == 1
    assert "broken_one" in err[0] and "No module named 'no_such_module_for_dbench'" in err[0]
