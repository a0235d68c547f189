"""Plugins at the edges of the contract (README.md, "Add your own denoiser"): entry points whose
name is not the method's, plugin code that raises where dbench asks it a question, classes
without a source file.

Nothing is pip-installed: an entry point is a ``*.dist-info`` folder (METADATA and
entry_points.txt) beside its package on a temporary path, which importlib.metadata finds.
"""
from __future__ import annotations

import sys
import textwrap
from pathlib import Path

import pytest

from dbench import cli, plugins, registry


def _install(site: Path, dist: str, package: str, code: str, entry_points: str) -> Path:
    """``package`` (its ``__init__.py`` holds ``code``) and the dist-info folder of ``dist``
    declaring ``entry_points`` on ``site``, and ``site`` on sys.path: what pip would do."""
    (site / package).mkdir(parents=True, exist_ok=True)
    (site / package / "__init__.py").write_text(textwrap.dedent(code))
    info = site / f"{dist}-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {dist}\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(textwrap.dedent(entry_points))
    sys.path.insert(0, str(site))
    return site


REGISTERED_AS = """\
    from dbench.registry import Denoiser, register


    @register("box-three")
    class Box3(Denoiser):
        def denoise(self, data):
            return data.color
    """


def test_an_entry_point_naming_a_class_registered_under_another_name_is_refused(
        isolated, tmp_path, capsys):
    # the entry point's name was dropped without a word: --method box3 was an "unknown method"
    # while `dbench list` showed box-three, and nothing joined the two names
    _install(tmp_path / "site", "ep-mismatch", "ep_mismatch", REGISTERED_AS,
             "[dbench.methods]\nbox3 = ep_mismatch:Box3\n")
    plugins.discover_entry_points()
    assert registry.method_class("box-three").name == "box-three"  # its own name works
    assert cli.main(["run", "--method", "box3", "--scene", "cornell"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("dbench: plugin box3 (entry point (ep-mismatch)"), err
    assert ("entry point 'box3' names ep_mismatch.Box3, which is registered as 'box-three': "
            "ask for --method box-three") in err[0]
    assert cli.main(["list"]) == 0
    listed = capsys.readouterr().out
    assert "box3         BROKEN" in listed and "registered as 'box-three'" in listed


def test_an_entry_point_naming_a_module_is_named_where_its_name_is_asked_for(isolated, tmp_path):
    # a module's entry point names the plugin, not a method: asking for it said only "unknown"
    _install(tmp_path / "site", "lab-methods", "lab_methods",
             REGISTERED_AS.replace("box-three", "lab-box"),
             "[dbench.methods]\nlab = lab_methods\n")
    plugins.discover_entry_points()
    with pytest.raises(registry.UnknownNameError) as caught:
        registry.method_class("lab")
    assert str(caught.value).endswith(
        "; plugin lab (entry point (lab-methods)) registered lab-box, not a method named lab")


APPLIES = '''
from dbench.registry import Denoiser, register


@register("asks-{name}")
class Asks(Denoiser):
    def applies_to(self, kind, available=None):
        {body}

    def denoise(self, data):
        return data.color
'''


@pytest.mark.parametrize("name, body, said", [
    ("raises", "raise RuntimeError('no model\\nfor this kind')",
     "failed in applies_to('steady'): RuntimeError: no model for this kind"),
    ("none", "return None", "applies_to('steady') returned None; expected (ok, reason)"),
    ("bool", "return True", "applies_to('steady') returned True; expected (ok, reason)")])
def test_a_plugin_applies_to_that_fails_is_refused_in_one_line(isolated, tmp_path, capsys,
                                                                name, body, said):
    # run and sweep ended with "internal error: RuntimeError: ..." (exit 1), and an answer
    # other than (ok, reason) with "cannot unpack non-iterable NoneType object"
    path = tmp_path / f"asks_{name}.py"
    path.write_text(APPLIES.format(name=name, body=body))
    for argv in (["run", "--method", f"asks-{name}", "--out", str(tmp_path / "run")],
                 ["sweep", "--methods", f"asks-{name}", "--spp", "2", "--res", "8",
                  "--out", str(tmp_path / "sweep")]):
        assert cli.main([*argv, "--scene" + ("s" if argv[0] == "sweep" else ""), "cornell",
                         "--plugin", str(path)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith(f"dbench: method asks-{name} ({path})") \
            and said in err[0], err
    assert not (tmp_path / "run").exists() and not (tmp_path / "sweep").exists()


def test_a_cell_whose_plugin_applies_to_raises_names_the_method(isolated, tmp_path):
    # where a cell asks it (a sweep's worker, the Python API) the method fails, named
    from dbench.run.harness import run_cell
    from dbench.synthetic import base_frame

    path = tmp_path / "asks_cell.py"
    path.write_text(APPLIES.format(name="cell", body="raise KeyError('kind')"))
    plugins.load(str(path))
    with pytest.raises(plugins.PluginError, match=r"^method asks-cell \(.*asks_cell.py\) failed "
                       r"in applies_to\('steady'\): KeyError: 'kind'$"):
        run_cell(registry.get("asks-cell"), base_frame(4, 4), repeats=1)



WANTS = '''
from dbench.registry import Denoiser, register


@register("wants-{name}")
class Wants(Denoiser):
    def wants(self, available):
        {body}

    def denoise(self, data):
        return data.color
'''


@pytest.mark.parametrize("name, body, said", [
    ("raises", "raise RuntimeError('no such\\nbuffer')",
     "failed in wants(['albedo', "),
    ("none", "return None", "wants() returned None; expected a set of buffer names")])
def test_a_plugin_wants_that_fails_is_refused_in_one_line(isolated, tmp_path, capsys, name,
                                                          body, said):
    # run ended with "internal error: RuntimeError: ..." (exit 1) when an overridden wants()
    # raised, as it did for applies_to (registry.applies)
    path = tmp_path / f"wants_{name}.py"
    path.write_text(WANTS.format(name=name, body=body))
    for argv in (["run", "--method", f"wants-{name}", "--scene", "cornell"],
                 ["sweep", "--methods", f"wants-{name}", "--scenes", "cornell"]):
        assert cli.main([*argv, "--res", "8", "--spp", "2", "--ref-spp", "4", "--out",
                         str(tmp_path / argv[0]), "--plugin", str(path)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith(f"dbench: method wants-{name} ({path})") \
            and said in err[0], err
        if name == "raises":
            assert err[0].endswith("RuntimeError: no such buffer"), err
    assert not (tmp_path / "run").exists() and not (tmp_path / "sweep").exists()


TYPED = """
from dbench.registry import Denoiser, register

SCALE = {scale}


def helper(x):
    return x * SCALE


@register("typed")
class Typed(Denoiser):
    kinds = {{"steady", "sequence"}}
    defaults = {{"passes": 1}}

    def denoise(self, data):
        return helper(data.color){tail}
"""


def _typed(monkeypatch, scale: float = 0.5, tail: str = "") -> type:
    """The class of TYPED as `python -c`, a prompt or a notebook defines it: in a ``__main__``
    without a file (its name free again for the next one)."""
    import types

    main = types.ModuleType("__main__")
    monkeypatch.setitem(sys.modules, "__main__", main)
    registry._REGISTRY.pop("typed", None)
    exec(compile(TYPED.format(scale=scale, tail=tail), "<stdin>", "exec"), main.__dict__)
    return main.Typed


def test_a_class_without_a_source_file_is_versioned_by_its_compiled_code(isolated, monkeypatch):
    # method_version raised OSError ("source code not available"), or FileNotFoundError for
    # `python - < file` ('<stdin>'): a sweep of such a method ended as an internal error
    from dbench.run import identity

    first = identity.method_version(_typed(monkeypatch))
    assert first.startswith("source-unknown-")
    assert identity.method_version(_typed(monkeypatch)) == first  # typed again: the same code
    assert identity.method_version(_typed(monkeypatch, scale=0.25)) != first  # a constant used
    assert identity.method_version(_typed(monkeypatch, tail=" * 2")) != first  # the method
    cls = _typed(monkeypatch)
    cls.version = "2"
    assert identity.method_version(cls).startswith("2+source-unknown-")


def test_a_class_typed_in_python_c_keeps_its_version_from_process_to_process(tmp_path):
    # the version of the same code, typed again in another process, lets a sweep reuse its
    # cells: no set order (it follows the string hash, another in every process) nor address
    import os
    import subprocess

    code = TYPED.format(scale=0.5, tail="") + (
        "from dbench.run import identity\nprint(identity.method_version(Typed))\n")
    env = {k: v for k, v in os.environ.items() if k != plugins.ENV_VAR}
    versions = {subprocess.run([sys.executable, "-c", code], env={**env, "PYTHONHASHSEED": seed},
                               capture_output=True, text=True, timeout=120).stdout.strip()
                for seed in ("1", "2")}
    assert len(versions) == 1 and versions.pop().startswith("source-unknown-"), versions


EDITED = '''
from dbench.registry import Denoiser, register


@register("edited")
class Edited(Denoiser):
    def denoise(self, data):
        return data.color * {scale}
'''


@pytest.mark.mitsuba  # the plan fingerprints the scene (Mitsuba's dictionary)
@pytest.mark.parametrize("removed", [False, True])
def test_a_plugin_edited_during_a_sweep_is_refused_not_scored_under_the_old_code(
        renderer, isolated, tmp_path, monkeypatch, removed):
    # a pool worker read the plugin after the sweep hashed it, and filed its numbers under the
    # old code's identity (a file removed meanwhile: FileNotFoundError ended the sweep). The
    # workers start afresh (sweep_pool._start_method) and load the plugin themselves: an edited
    # file is refused by its hash, a removed one as a method the worker could not build
    from dbench.run import identity, sweep

    path = tmp_path / "edited.py"
    path.write_text(EDITED.format(scale=1.0))
    plugins.load(str(path))
    planned = sweep.plan

    def plan_then_edit(config, out):  # the user saves the file while the sweep starts
        groups = planned(config, out)
        path.unlink() if removed else path.write_text(EDITED.format(scale=0.5))
        return groups

    monkeypatch.setattr(sweep, "plan", plan_then_edit)
    old = identity.method_version(registry.method_class("edited"))
    config = sweep.SweepConfig(methods=["noisy", "edited"], scenes=["cornell"], spp=[2, 3],
                               res=8, ref_spp=16, repeats=1, cache=str(tmp_path / "cache"))
    counts = sweep.run_sweep(config, tmp_path / "S", workers=2, progress=False)
    identity.method_version.cache_clear()  # the file as it is now
    new = identity.method_version(registry.method_class("edited"))
    assert new != old and new.startswith("source-unknown-") == removed
    assert counts["errors"] == 2, counts
    cells = [c for c in sweep.load_cells(tmp_path / "S") if c["method"] == "edited"]
    if removed:
        assert all(c["error"].startswith("edited: not built in this sweep's worker (plugin ")
                   and "edited.py" in c["error"]
                   and c["error"].endswith("; not scored: run the sweep again") for c in cells)
    else:
        assert [c["error"] for c in cells] == [
            f"edited: its code changed during the sweep (method_version {old} -> {new}); not "
            f"scored: run the sweep again"] * 2
    assert {c["status"] for c in sweep.load_cells(tmp_path / "S") if c["method"] == "noisy"} \
        == {"ok"}


SAME = """
from dbench.registry import Denoiser, register


@register("{name}")
class Same(Denoiser):
    def denoise(self, data):
        return data.color
"""


@pytest.mark.parametrize("name, holder", [
    ("twice", "Same ({first})"), ("jbf", "JBF ({root}/dbench/methods/jbf/__init__.py)")])
def test_a_name_taken_is_refused_naming_both_files(isolated, tmp_path, capsys, name, holder):
    # "plugin same.py (--plugin) failed to load: ValueError: method 'twice' registered twice":
    # neither which same.py nor who held the name
    first, second = tmp_path / "a" / "same.py", tmp_path / "b" / "same.py"
    for path in (first, second):
        path.parent.mkdir()
        path.write_text(SAME.format(name=name))
    specs = ["--plugin", str(second)] if name == "jbf" else \
        ["--plugin", str(first), "--plugin", str(second)]
    assert cli.main(["run", "--method", name, "--scene", "cornell", *specs]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    said = holder.format(first=first, root=Path(__file__).resolve().parents[1])
    assert err == [f"dbench: plugin {second} (--plugin) failed to load: ValueError: method "
                   f"{name!r} is already registered by {said}"], err


def test_one_class_registered_under_two_names_is_refused(isolated, tmp_path):
    # the class took the second name: --method first-name ran, skipped and failed as
    # "second-name", its cells filed under one name and its messages under the other
    path = tmp_path / "two_names.py"
    path.write_text(SAME.format(name="second-name").replace(
        '@register("second-name")', '@register("second-name")\n@register("first-name")'))
    with pytest.raises(plugins.PluginError) as caught:
        plugins.load(str(path))
    assert str(caught.value).endswith(
        f"ValueError: method 'second-name': Same ({path}) is registered as 'first-name' "
        f"already; a class has one name (register a subclass under the second)")


@pytest.mark.parametrize("kinds", ['{"stedy"}', '"transient"', "None"])
def test_kinds_a_plugin_sets_when_it_is_built_are_checked_as_its_class_is(isolated, tmp_path,
                                                                         capsys, kinds):
    # register() checks the class's kinds; set in __init__, a misspelt kind skipped the method
    # on every scene, a string was read by its letters and None ended run as an internal error
    path = tmp_path / "late_kinds.py"
    path.write_text(SAME.format(name="late-kinds").replace(
        "    def denoise", f"    def __init__(self, **params):\n        super().__init__(**params)"
        f"\n        self.kinds = {kinds}\n\n    def denoise"))
    out = tmp_path / "run"
    assert cli.main(["run", "--method", "late-kinds", "--scene", "cornell", "--plugin",
                     str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"dbench: method late-kinds ({path}) could not be built: method "
                   f"'late-kinds': kinds {eval(kinds)!r}; expected a non-empty set of steady, "
                   f"sequence, transient"], err
    assert not out.exists()


def test_one_entry_point_name_declared_by_two_distributions_is_refused_naming_both(
        isolated, tmp_path, capsys):
    # the distribution found later on sys.path was dropped without a word: --method twin ran
    # whichever came first
    for dist, package in (("twin-a", "twin_a"), ("twin-b", "twin_b")):
        _install(tmp_path / dist, dist, package, REGISTERED_AS.replace(
            '    @register("box-three")\n', ""), f"[dbench.methods]\ntwin = {package}:Box3\n")
    plugins.discover_entry_points()
    assert "twin" not in registry.available()
    assert cli.main(["run", "--method", "twin", "--scene", "cornell"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["dbench: plugin twin (entry points (twin-b, twin-a), twin_b:Box3, "
                   "twin_a:Box3) failed to load: ValueError: entry point 'twin' is declared by "
                   "twin-b (twin_b:Box3) and by twin-a (twin_a:Box3); uninstall one of them, or "
                   "give one another name"], err


def test_a_version_a_plugin_sets_when_it_is_built_is_refused(isolated, tmp_path, capsys):
    # method_version reads the class attribute: self.version (of the weights it loaded, say)
    # was dropped without a word, and cells of other weights were reused as these
    path = tmp_path / "late_version.py"
    path.write_text(SAME.format(name="late-version").replace(
        "    def denoise", "    version = 1\n\n    def __init__(self, **params):\n"
        "        super().__init__(**params)\n        self.version = 'weights-2'\n\n    def denoise"))
    out = tmp_path / "run"
    assert cli.main(["run", "--method", "late-version", "--scene", "cornell", "--plugin",
                     str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"dbench: method late-version ({path}) could not be built: version "
                   f"'weights-2' set in __init__ is not read: a result's identity holds the "
                   f"class attribute version; set it there"], err
    assert not out.exists()


@pytest.fixture
def broken_entry_point(isolated, tmp_path):
    """A method entry point whose module fails to import (dbench list: "Broken plugins")."""
    _install(tmp_path / "site", "lab-broken", "lab_broken",
             "raise ImportError('needs libfoo')\n", "[dbench.methods]\nlab-box = lab_broken:Box\n")
    plugins.discover_entry_points()
    return "plugin lab-box (entry point (lab-broken), lab_broken:Box) failed to load: " \
           "ImportError: needs libfoo"


def test_all_names_the_method_plugins_it_leaves_out(broken_entry_point, tmp_path, capsys,
                                                    monkeypatch):
    # --method all / --methods all ran every method that loaded without a word of the broken
    # ones; now one line on stderr (and a note in run's report.md) names each and why
    from dbench.cli import run as cli_run
    from dbench.run import sweep
    from dbench.stress import runner

    def stand_in(*a, **k):
        raise plugins.PluginError("stand-in: nothing runs here")

    monkeypatch.setattr(sweep, "run_sweep", stand_in)
    monkeypatch.setattr(runner, "run_all", stand_in)
    for argv, option in ((["sweep", "--methods", "all", "--scenes", "cornell", "--spp", "2"],
                          "--methods"), (["stress"], "--methods")):
        assert cli.main([*argv, "--out", str(tmp_path / "out")]) == 2
        err = capsys.readouterr().err.splitlines()
        assert err == [f"dbench: warning: {option} all leaves out what these plugins hold: "
                       f"{broken_entry_point}", "dbench: stand-in: nothing runs here"], err
    # a plain list asks for no "all": nothing to say
    assert cli.main(["stress", "--methods", "jbf", "--out", str(tmp_path / "out")]) == 2
    assert capsys.readouterr().err.splitlines() == ["dbench: stand-in: nothing runs here"]
    seen = []
    monkeypatch.setattr(cli_run, "run_scene", lambda stage, req, *a: seen.append(req.notes)
                        or stand_in())
    assert cli.main(["run", "--method", "all", "--scene", "cornell", "--res", "8", "--spp",
                     "2", "--out", str(tmp_path / "run")]) == 2
    said = f"--method all leaves out what these plugins hold: {broken_entry_point}"
    assert capsys.readouterr().err.splitlines()[0] == f"dbench: warning: {said}"
    assert seen == [(said,)]


def test_a_run_report_notes_the_plugins_all_leaves_out(broken_entry_point, tmp_path,
                                                       monkeypatch):
    from dbench import registry

    # "all" as the noisy input and one method: enough to write report.md, and fast
    monkeypatch.setattr(registry, "available", lambda: ["noisy", "jbf"])
    assert cli.main(["run", "--method", "all", "--scene", "cornell", "--res", "8", "--spp",
                     "2", "--ref-spp", "4", "--repeats", "1", "--quiet", "--out",
                     str(tmp_path / "run")]) == 0
    report = (tmp_path / "run" / "report.md").read_text()
    assert f"- --method all leaves out what these plugins hold: {broken_entry_point}" in report


def test_a_scene_entry_point_that_failed_to_load_is_named_where_it_is_asked_for(
        isolated, tmp_path, capsys):
    # --scene NAME of a broken scene entry point said only "unknown scene 'NAME'"
    _install(tmp_path / "site", "lab-rooms", "lab_rooms", "raise ImportError('needs libbar')\n",
             "[dbench.scenes]\nlab-room = lab_rooms:room\n")
    plugins.discover_entry_points()
    why = ("scene 'lab-room': plugin lab-room (entry point (lab-rooms), lab_rooms:room) failed "
           "to load: ImportError: needs libbar")
    for argv in (["run", "--method", "noisy", "--scene", "lab-room"],
                 ["sweep", "--methods", "noisy", "--scenes", "cornell,lab-room"],
                 ["render", "--scene", "lab-room"]):
        out = ["--out", str(tmp_path / "out")] if argv[0] != "render" else []
        assert cli.main([*argv, *out]) == 2
        assert capsys.readouterr().err.splitlines() == [f"dbench: {why}"]
    assert not (tmp_path / "out").exists()


@pytest.fixture
def broken_scene_entry_point(isolated, tmp_path):
    """A scene entry point whose module fails to import (dbench list: "Broken plugins")."""
    _install(tmp_path / "site", "lab-rooms", "lab_rooms", "raise ImportError('needs libbar')\n",
             "[dbench.scenes]\nlab-room = lab_rooms:room\n")
    plugins.discover_entry_points()
    return "plugin lab-room (entry point (lab-rooms), lab_rooms:room) failed to load: " \
           "ImportError: needs libbar"


def test_all_names_the_scene_plugins_it_leaves_out(broken_scene_entry_point, tmp_path, capsys,
                                                   monkeypatch):
    # --scenes all swept every scene that loaded without a word of the broken scene plugins
    # (left_out names the method plugins only); now one line on stderr, and the run's entry in
    # sweep.json keeps it for the report
    from dbench import datasets
    from dbench.run import sweep

    seen = []

    def stand_in(config, *a, **k):
        seen.append(config.notes)
        raise plugins.PluginError("stand-in: nothing runs here")

    monkeypatch.setattr(sweep, "run_sweep", stand_in)
    said = f"--scenes all leaves out these scene plugins: {broken_scene_entry_point}"
    assert cli.main(["sweep", "--methods", "noisy", "--scenes", "all", "--spp", "2", "--out",
                     str(tmp_path / "out")]) == 2
    assert capsys.readouterr().err.splitlines() == [
        f"dbench: warning: {said}", "dbench: stand-in: nothing runs here"]
    assert seen == [[said]]
    # the methods' line leaves the scene plugin out, as before
    assert plugins.left_out("--methods") == ""
    # a plain list asks for no "all": nothing to say
    assert cli.main(["sweep", "--methods", "noisy", "--scenes", "cornell", "--spp", "2",
                     "--out", str(tmp_path / "out")]) == 2
    assert capsys.readouterr().err.splitlines() == ["dbench: stand-in: nothing runs here"]
    assert seen[-1] == []
    # render's --scene all (its default) says it too, before it renders anything
    monkeypatch.setattr(datasets, "load", lambda *a, **k: stand_in(
        type("Config", (), {"notes": "render"})))
    assert cli.main(["render", "--res", "8", "--cache", str(tmp_path / "cache")]) == 2
    assert capsys.readouterr().err.splitlines() == [
        f"dbench: warning: --scene all leaves out these scene plugins: "
        f"{broken_scene_entry_point}", "dbench: stand-in: nothing runs here"]
