"""A list option given more than once adds each list's items, as ``sweep --scenes`` does, and
``run --scene`` (one scene a run) given twice is refused in one line (dbench.cli.args.list_items,
dbench.options.Once; README.md, "Usage"): ``run --method noisy --method jbf`` ran jbf alone,
``sweep --methods``, ``stress --methods`` and ``render --scene`` kept their last list and
``run --scene cornell --scene textured`` ran textured, each without a word.

The work itself is replaced by stand-ins that record what they were given and stop."""
from __future__ import annotations

import pytest

from dbench import cli
from dbench.errors import DbenchInputError


@pytest.fixture
def given(monkeypatch):
    """What ``run``, ``sweep``, ``stress`` and ``render`` would run: the methods (or scenes)
    their work was handed, before a stand-in refuses."""
    from dbench import datasets
    from dbench.cli import run as cli_run
    from dbench.run import sweep
    from dbench.stress import runner

    seen: list[list[str]] = []

    def record(names):
        seen.append(list(names))
        raise DbenchInputError("stand-in: nothing runs here")

    monkeypatch.setattr(cli_run, "run_scene", lambda stage, req, scene, instances, *a, **k:
                        record(instances))
    monkeypatch.setattr(sweep, "run_sweep", lambda config, out, **k: record(config.methods))
    monkeypatch.setattr(runner, "run_all", lambda names, **k: record(names))
    monkeypatch.setattr(datasets, "load", lambda scene, **k: record([scene.name]))
    return seen


@pytest.mark.parametrize("argv, names", [
    (["run", "--method", "jbf", "--method", "statistical", "--scene", "cornell", "--res", "8",
      "--spp", "2", "--ref-spp", "4"], ["noisy", "jbf", "statistical"]),
    (["sweep", "--methods", "jbf", "--methods", "noisy,statistical", "--scenes", "cornell",
      "--spp", "2"], ["jbf", "noisy", "statistical"]),
    (["stress", "--methods", "jbf", "--methods", "statistical"], ["jbf", "statistical"]),
    (["render", "--scene", "cornell", "--scene", "textured", "--res", "8", "--spp", "2"],
     ["cornell"]),
])
def test_a_list_option_given_twice_adds_its_items(tmp_path, given, capsys, argv, names):
    out = ["--out", str(tmp_path / "out")] if argv[0] in ("run", "sweep", "stress") else []
    assert cli.main([*argv, *out]) == 2
    assert "stand-in" in capsys.readouterr().err
    assert given == [names]
    if argv[0] == "render":  # the first scene reached the stand-in: the second was kept too
        from dbench.cli.scene_list import scene_names

        assert scene_names(["cornell", "textured"], "--scene") == ["cornell", "textured"]


@pytest.mark.parametrize("argv, said", [
    (["run", "--method", "jbf", "--method", "jbf", "--scene", "cornell"],
     "--method: 'jbf' is given twice in 'jbf jbf'"),
    (["run", "--method", "statistical-gate", "--method", "statistical+gate", "--scene",
      "cornell"], "'statistical-gate' and 'statistical+gate' name the same item"),
    (["run", "--method", "all", "--method", "jbf", "--scene", "cornell"],
     "--method: 'all jbf'; 'all' stands alone"),
    (["sweep", "--methods", "jbf", "--methods", "noisy,jbf", "--scenes", "cornell"],
     "--methods: 'jbf' is given twice in 'jbf noisy,jbf'"),
    (["stress", "--methods", "jbf", "--methods", "all"], "'all' stands alone"),
    (["render", "--scene", "cornell", "--scene", "cornell"], "--scene: 'cornell' is given twice"),
    (["run", "--method", "noisy", "--scene", "cornell", "--scene", "textured"],
     "--scene: given twice ('cornell', 'textured'); dbench run takes one --scene"),
    (["run", "--method", "noisy", "--method", "", "--scene", "cornell"], "--method: empty ('')"),
])
def test_repeated_list_options_refuse_what_one_list_refuses(tmp_path, given, capsys, argv, said):
    argv = [*argv, "--out", str(tmp_path / "out")] if argv[0] != "render" else argv
    try:
        rc = cli.main(argv)
    except SystemExit as exc:  # the parser's refusal (dbench.cli.parser.Parser.error)
        rc = exc.code
    assert rc == 2
    err = capsys.readouterr().err
    assert err.startswith("dbench: ") and said in err and err.count("\n") == 1, err
    assert given == [] and not (tmp_path / "out").exists()
