"""Exit codes say what happened: code from outside dbench (a scene file, a plugin) never ends
the process with its own code, the user's situation gets one line and exit 2 (or, for a cache
folder from the environment that cannot be written, a warning and an uncached run), absurd
counts are refused before anything renders, ``--quiet`` prints no progress bar and outputs of
NaN or 3e38 print no NumPy warnings (README.md, "Python scene files" and "How renders work")."""
from __future__ import annotations

import os
import subprocess
import sys
import warnings
from pathlib import Path

import pytest
from cli_args import with_options  # tests/cli_args.py

from dbench import cli, plugins

ROOT = Path(__file__).resolve().parents[2]
TINY = ["--res", "8", "--spp", "2", "--ref-spp", "16", "--repeats", "1", "--quiet"]


def _dbench(tmp_path, *args, env=None):
    env = {**os.environ, "DBENCH_CACHE": str(tmp_path / "cache"), **(env or {})}
    env.pop(plugins.ENV_VAR, None)
    return subprocess.run([sys.executable, "-m", "dbench.cli", *args], env=env, cwd=ROOT,
                          capture_output=True, text=True, timeout=600)


def _nothing_rendered(cache: Path) -> bool:
    """No cache entry under ``cache`` (the renderer's start-up probe may write its note)."""
    return not cache.exists() or all(p.is_file() for p in cache.iterdir())


def _one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("dbench: "), err
    assert "Traceback" not in err and "internal error" not in err, err
    return lines[0]


# ---------------------------------------------------------------------------------------------
# code from outside dbench calling sys.exit


@pytest.mark.mitsuba
@pytest.mark.parametrize("where", ["import", "build"])
def test_a_scene_file_calling_sys_exit_exits_2_naming_it(renderer, tmp_path, where):
    scene = tmp_path / "my_scene.py"
    scene.write_text("import sys\nsys.exit(0)\n" if where == "import" else
                     "import sys\n\ndef build(mi, width, height):\n    sys.exit(0)\n")
    out = tmp_path / "out"
    ran = _dbench(tmp_path, "run", "--method", "noisy", "--scene", str(scene), "--out",
                  str(out), *TINY)
    assert ran.returncode == 2, (ran.returncode, ran.stderr)
    line = _one_line(ran.stderr)
    assert "my_scene.py" in line and "sys.exit(0)" in line
    assert ("while loading" in line) == (where == "import")
    assert not out.exists() and _nothing_rendered(tmp_path / "cache")


def test_a_plugin_calling_sys_exit_at_import_exits_2_naming_it(tmp_path):
    plugin = tmp_path / "exiting_plugin.py"
    plugin.write_text("import sys\nsys.exit(3)\n")
    ran = _dbench(tmp_path, "--plugin", str(plugin), "run", "--method", "noisy", "--scene",
                  "cornell", "--out", str(tmp_path / "out"), *TINY)
    assert ran.returncode == 2, (ran.returncode, ran.stderr)
    line = _one_line(ran.stderr)
    assert "exiting_plugin.py" in line and "sys.exit(3)" in line
    assert not (tmp_path / "out").exists()


def test_plugins_calling_sys_exit_are_broken_not_fatal(isolated, tmp_path, monkeypatch,
                                                       capsys):
    plugin = tmp_path / "quits.py"
    plugin.write_text("raise SystemExit('bye')\n")
    record = plugins.load(str(plugin), strict=False)
    assert not record.ok and "sys.exit('bye')" in record.error
    with pytest.raises(plugins.PluginError, match="quits.py"):
        plugins.load(str(plugin))
    # through $DBENCH_PLUGINS: `list` shows it, any other command exits 2
    env_plugin = tmp_path / "quits_too.py"
    env_plugin.write_text("import sys\nsys.exit()\n")
    monkeypatch.setenv(plugins.ENV_VAR, str(env_plugin))
    plugins._STATE["discovered"] = False  # as in a fresh process
    assert cli.main(["list"]) == 0
    assert "quits_too.py" in capsys.readouterr().out
    assert cli.main(["run", "--method", "noisy", "--scene", "cornell",
                     "--out", str(tmp_path / "o"), *TINY]) == 2
    line = _one_line(capsys.readouterr().err)
    assert "quits_too.py" in line and "sys.exit()" in line
    assert not (tmp_path / "o").exists()


def test_sys_exit_anywhere_else_in_a_command_exits_2_naming_the_caller(isolated, tmp_path,
                                                                      capsys):
    plugin = tmp_path / "exits_when_made.py"
    plugin.write_text(
        "import sys\n"
        "from dbench.registry import Denoiser, register\n\n\n"
        "@register('exits-when-made')\n"
        "class ExitsWhenMade(Denoiser):\n"
        "    def __init__(self, **params):\n"
        "        sys.exit(0)\n")
    rc = cli.main(["--plugin", str(plugin), "run", "--method", "exits-when-made", "--scene",
                   "cornell", "--cache", str(tmp_path / "cache"), "--out",
                   str(tmp_path / "out"), *TINY])
    line = _one_line(capsys.readouterr().err)
    assert rc == 2 and f"{plugin}:8 called sys.exit(0) during dbench run" in line, line
    assert not (tmp_path / "out").exists()


def test_a_plugin_scene_build_calling_sys_exit_is_an_input_error(isolated, renderer):
    from dbench.datasets.scenes import catalogue as scenes
    from dbench.errors import DbenchInputError

    def quitting(mi, res):
        raise SystemExit(0)

    plugins._register_scene_object("quitting-room", quitting)
    with pytest.raises(DbenchInputError, match=r"scene quitting-room: .*sys\.exit\(0\)"):
        scenes.get("quitting-room").scene_dict(renderer, 8)


# ---------------------------------------------------------------------------------------------
# the user's situation: one line and exit 2, or carry on


@pytest.mark.mitsuba
def test_unknown_mitsuba_plugin_in_a_scene_file_exits_2_naming_file_and_type(renderer,
                                                                            tmp_path, capsys):
    scene = tmp_path / "odd_scene.py"
    scene.write_text(
        "def build(mi, width, height):\n"
        "    d = mi.cornell_box()\n"
        "    d['blob'] = {'type': 'no_such_shape_in_mitsuba'}\n"
        "    return d\n")
    rc = cli.main(["run", "--method", "noisy", "--scene", str(scene), "--out",
                   str(tmp_path / "out"), "--cache", str(tmp_path / "cache"), *TINY])
    line = _one_line(capsys.readouterr().err)
    assert rc == 2 and "odd_scene.py" in line and '"no_such_shape_in_mitsuba"' in line
    assert '"blob"' in line
    assert not (tmp_path / "out").exists() and _nothing_rendered(tmp_path / "cache")


def _cache_blockers(tmp_path: Path) -> list[Path]:
    blocker = tmp_path / "a-file"
    blocker.write_text("x")
    out = [blocker, blocker / "below-a-file"]
    if os.geteuid() != 0:  # root writes into read-only folders
        ro = tmp_path / "read-only"
        ro.mkdir()
        ro.chmod(0o555)
        out.append(ro)
    return out


@pytest.mark.mitsuba
def test_an_unwritable_cache_from_the_environment_warns_and_runs_uncached(
        renderer, tmp_path, monkeypatch, capsys):
    for k, blocked in enumerate(_cache_blockers(tmp_path)):
        monkeypatch.setenv("DBENCH_CACHE", str(blocked))
        out = tmp_path / f"out{k}"
        rc = cli.main(["run", "--method", "noisy", "--scene", "cornell", "--out", str(out),
                       *TINY])
        err = capsys.readouterr().err
        assert rc == 0, err
        warning = [ln for ln in err.splitlines() if ln.strip()]
        assert len(warning) == 1 and warning[0].startswith("dbench: warning: $DBENCH_CACHE")
        assert str(blocked) in warning[0] and "without the cache" in warning[0]
        assert (out / "metrics.csv").is_file()
    # a sweep shares renders between workers through the cache: it refuses, in one line
    rc = cli.main(["sweep", "--methods", "noisy", "--scenes", "cornell", "--spp", "2",
                   "--res", "8", "--ref-spp", "16", "--out", str(tmp_path / "sweep"),
                   "--quiet"])
    assert rc == 2 and "--cache" in _one_line(capsys.readouterr().err)


def test_an_unwritable_cache_named_on_the_command_line_exits_2(tmp_path, capsys):
    blocker = tmp_path / "a-file"
    blocker.write_text("x")
    rc = cli.main(["run", "--method", "noisy", "--scene", "cornell", "--cache", str(blocker),
                   "--out", str(tmp_path / "out"), *TINY])
    assert rc == 2 and "--cache" in _one_line(capsys.readouterr().err)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("extra, option, valid", [
    (["--ref-spp", "1e20"], "--ref-spp", "[2, 2147483647]"),
    (["--ref-spp", "1"], "--ref-spp", "[2, 2147483647]"),
    (["--spp", "0"], "--spp", "[1, 2147483647]"),
    (["--spp", "-4"], "--spp", "[1, 2147483647]"),
    (["--ref-spp", "many"], "--ref-spp", "[2, 2147483647]"),
    (["--seeds", "1e20"], "--seeds", "[1, 2147483647]"),
    (["--repeats", "99999999999"], "--repeats", "[1, 2147483647]"),
    (["--bins", "10000000"], "--bins", "[1, 87381]"),
    (["--bins", "0"], "--bins", "[1, 2147483647]"),
    (["--frames", "1e9999"], "--frames", "[1, 2147483647]"),
])
def test_absurd_counts_exit_2_in_one_line_before_rendering(tmp_path, capsys, monkeypatch,
                                                           extra, option, valid):
    from dbench import datasets

    def no_rendering(*a, **k):
        raise AssertionError("rendered despite a bad count")
    monkeypatch.setattr(datasets, "load", no_rendering)
    argv = with_options(["run", "--method", "noisy", "--scene", "cornell-transient", "--res",
                         "16", "--spp", "4", "--cache", str(tmp_path / "cache"), "--out",
                         str(tmp_path / "out"), "--quiet"], *extra)
    rc = cli.main(argv)
    line = _one_line(capsys.readouterr().err)
    assert rc == 2 and line.startswith(f"dbench: {option}: ") and valid in line, line
    assert _nothing_rendered(tmp_path / "cache") and not (tmp_path / "out").exists()


def test_counts_accept_exponent_notation_of_whole_numbers():
    from dbench.cli.bounds import BadCount, count

    assert count("1e3") == 1000 and count(" 64 ") == 64 and count("2147483647") == 2**31 - 1
    for bad in ("1e20", "0", "1.5", "nan", "inf", "", "2147483648"):
        assert isinstance(count(bad), BadCount), bad


def test_sweep_spp_lists_are_bounded_too(tmp_path, capsys):
    rc = cli.main(["sweep", "--methods", "noisy", "--scenes", "cornell", "--spp", "4,1e20",
                   "--res", "8", "--cache", str(tmp_path / "cache"), "--out",
                   str(tmp_path / "sweep"), "--quiet"])
    line = _one_line(capsys.readouterr().err)
    assert rc == 2 and "--spp" in line and "[1, 2147483647]" in line
    assert not (tmp_path / "sweep").exists()


@pytest.mark.mitsuba
def test_the_transient_loader_refuses_a_film_too_large_before_rendering(tr, tmp_path):
    from dbench.datasets import Cache
    from dbench.datasets.transient.scene import MAX_TRANSIENT_FILM_BYTES, check_bins, max_bins
    from dbench.errors import DbenchInputError

    assert max_bins(16) * 16 * 16 * 3 * 4 <= MAX_TRANSIENT_FILM_BYTES
    assert (max_bins(16) + 1) * 16 * 16 * 3 * 4 > MAX_TRANSIENT_FILM_BYTES
    assert check_bins(200, 128) == 200
    with pytest.raises(DbenchInputError, match=r"bins: expected an integer in \[1, \d+\] at"):
        tr.load_transient("cornell-transient", spp=2, res=16, bins=10**7,
                          cache=Cache(tmp_path / "cache"))
    assert _nothing_rendered(tmp_path / "cache")


# ---------------------------------------------------------------------------------------------
# quiet runs and non-finite outputs


_BARS = ("%|", "it/s", "pass/s", "spp/s")


@pytest.mark.mitsuba
@pytest.mark.parametrize("scene, extra", [
    # 16 passes and 16 reference chunks; 4 frames: the smallest counts that show a bar
    ("cornell", ["--spp", "16", "--ref-spp", "256"]),
    ("cornell-transient", ["--spp", "16", "--ref-spp", "256", "--bins", "8"]),
    ("orbit", ["--spp", "1", "--ref-spp", "16", "--frames", "4"]),
])
def test_quiet_runs_print_no_progress_bar(renderer, tmp_path, capsys, scene, extra):
    # --no-cache below (no --cache beside it: the two together are refused)
    argv = ["run", "--method", "noisy", "--scene", scene, "--res", "8", "--repeats", "1",
            "--out", str(tmp_path / "out"), *extra]
    if scene == "cornell-transient":
        from dbench.datasets import mitsuba_env
        if not mitsuba_env.mitsuba().variant().startswith(("llvm", "cuda")):
            pytest.skip("transient rendering needs the llvm_ad_rgb variant")
    if scene == "cornell":  # the check is meaningful: without --quiet there is a bar
        assert cli.main(argv + ["--no-cache"]) == 0
        assert any(b in capsys.readouterr().err for b in _BARS)
    assert cli.main(argv + ["--quiet", "--no-cache"]) == 0
    err = capsys.readouterr().err
    assert not any(b in err for b in _BARS), err


EXTREME = '''
import numpy as np
from dbench.registry import Denoiser, register


@register("{prefix}-nan")
class Nan(Denoiser):
    kinds = {{"steady", "transient"}}
    needs = {{"color"}}

    def denoise(self, data):
        out = np.array(data.color, dtype=np.float32)
        out[0, 0] = np.nan
        return out


@register("{prefix}-huge")
class Huge(Denoiser):
    kinds = {{"steady", "transient"}}
    needs = {{"color"}}

    def denoise(self, data):
        out = np.full(np.shape(data.color), 3e38, np.float32)
        out[1, 1] = np.inf
        return out
'''


@pytest.mark.mitsuba
@pytest.mark.parametrize("scene", ["cornell", "cornell-transient"])
def test_nan_and_3e38_outputs_print_no_numpy_warnings(isolated, renderer, tmp_path, capsys,
                                                      scene):
    plugin = tmp_path / "extreme.py"
    plugin.write_text(EXTREME.format(prefix=f"extreme-{scene}"))
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        rc = cli.main(["--plugin", str(plugin), "run", "--method",
                       f"extreme-{scene}-nan,extreme-{scene}-huge", "--scene", scene,
                       *(["--bins", "8"] if scene.endswith("transient") else []),
                       "--cache", str(tmp_path / "cache"), "--out",
                       str(tmp_path / "out"), *TINY])
    err = capsys.readouterr().err
    assert rc == 0, err
    numpy_warnings = [str(w.message) for w in seen if issubclass(w.category, RuntimeWarning)]
    assert not numpy_warnings and "RuntimeWarning" not in err, numpy_warnings or err


@pytest.mark.parametrize("value", ["lots", "0", "1", "-64", str(2**31)])
def test_a_bad_reference_spp_from_the_environment_is_one_line(tmp_path, value):
    """DBENCH_REF_SPP is read as --ref-spp is: anything but a count of at least 2 is refused,
    naming it (1 spp is one chunk, whose spread would read as a noise-free reference)."""
    args = ["run", "--method", "noisy", "--scene", "cornell", "--res", "8", "--spp", "2",
            "--repeats", "1", "--quiet", "--out", str(tmp_path / "out")]
    r = _dbench(tmp_path, *args, env={"DBENCH_REF_SPP": value})
    assert r.returncode == 2, r.stderr
    line = _one_line(r.stderr)
    assert "DBENCH_REF_SPP" in line and repr(value) in line and "[2, 2147483647]" in line
    assert _nothing_rendered(tmp_path / "cache") and not (tmp_path / "out").exists()


def test_a_path_this_user_may_not_read_exits_2_in_one_line(tmp_path, monkeypatch, capsys):
    """A scene file (or folder, or results folder) the user may not read was an internal error
    (exit 1); it is the input's problem: one line naming the path, exit 2. (Tests run as root
    read through permissions, so the refusal is raised where the file is opened.)"""
    from dbench import cli
    from dbench.datasets.scene_files import load as scene_files

    path = tmp_path / "unread.xml"
    path.write_text("<scene/>")

    def denied(*_a, **_k):
        raise PermissionError(13, "Permission denied", str(path))

    monkeypatch.setattr(scene_files, "resolve", denied)
    rc = cli.main(["run", "--method", "noisy", "--scene", str(path), "--res", "8", "--spp", "2",
                   "--out", str(tmp_path / "out"), "--cache", str(tmp_path / "cache")])
    err = capsys.readouterr().err
    assert rc == 2 and err == f"dbench: cannot access {path}: Permission denied\n", err
    assert not (tmp_path / "out").exists()
