"""sweep.json keeps the history of every run into the folder; a sweep.json that cannot be read
is refused, named, and left as it is; the reference spp is compared as it is in effect."""
import json

import pytest

from dbench import cli
from dbench.run import sweep, sweep_history
from dbench.errors import DbenchInputError


def _config(tmp_path, **kw):
    base = dict(methods=["noisy"], scenes=["cornell"], spp=[2], res=8, ref_spp=16, repeats=1,
                cache=str(tmp_path / "cache"))
    base.update(kw)
    return sweep.SweepConfig(**base)


def _stored(out):
    return json.loads((out / "sweep.json").read_text())


@pytest.mark.parametrize("text, problem", [
    ('{"config": {"spp": [2], "res"', "not valid JSON"),
    ('{"config": {"spp": "abc", "res": 8}, "runs": []}', 'config.spp is "abc", not a list'),
    ('[1, 2]', "not a JSON object"),
    ('{"config": {"spp": [2]}, "runs": {}}', "runs is {}, not a list of objects"),
    ('{"runs": []}', "config is missing"),
    ('{"config": [], "runs": []}', "config is [], not an object"),
    ('{"config": {"params": []}}', "config.params is [], not an object ({method: "),
    ('{"config": {"params": {"jbf": 3}}}', "config.params.jbf is 3, not an object"),
    ('{"config": {"spp": [2]}, "machine": "x"}', 'machine is "x", not an object (cpu, '),
    ('{"config": {}, "machine": {"cores": "2"}}', 'machine.cores is "2", not an integer'),
    ('{"config": {}, "machine": {"packages": ["numpy"]}}',
     'machine.packages is ["numpy"], not an object ({package: version})'),
    ('{"config": {"series": {"jbf": {"method": 3}}}}',
     "config.series.jbf.method is 3, not a name"),
    ('{"config": {"series": []}}', "config.series is [], not an object ({label: "),
    ('{"config": {"scene_labels": {"cornell": 1}}}',
     "config.scene_labels.cornell is 1, not a name"),
    ('{"config": {"scene_params": {"spp": [1]}}}',
     "config.scene_params.spp is [1], not a value (string or number)"),
    ('{"config": {"lam": "0.5"}}', 'config.lam is "0.5", not a number'),
    ('{"config": {}, "runs": [1]}', "runs[0] is 1, not an object"),
    ('{"config": {}, "runs": [{"cells": "many"}]}', 'runs[0].cells is "many", not an integer'),
    ('{"config": {}, "runs": [{}, {"status": "paused"}]}',
     'runs[1].status is "paused", not one of running, finished, interrupted, failed, killed'),
    ('{"config": {}, "runs": [{"request": {"spp": 2}}]}',
     "runs[0].request.spp is 2, not a list of integers"),
    ('{"config": {}, "runs": [{"wall_s": null}]}', "runs[0].wall_s is null, not a number"),
])
def test_a_broken_sweep_json_is_refused_and_left_unchanged(tmp_path, capsys, text, problem):
    out = tmp_path / "S"
    out.mkdir()
    (out / "sweep.json").write_text(text)
    before = (out / "sweep.json").read_bytes()
    rc = cli.main(["sweep", "--methods", "noisy", "--scenes", "cornell", "--spp", "2",
                   "--res", "8", "--out", str(out), "--quiet", "--cache", str(tmp_path / "c")])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1, err
    assert str(out / "sweep.json") in err and problem in err and "internal error" not in err
    assert (out / "sweep.json").read_bytes() == before
    assert sorted(p.name for p in out.iterdir()) == ["sweep.json"]
    assert not (tmp_path / "c").exists()


def _fields(value, place=(), where=""):
    """(place, name) of every field of a parsed sweep.json, objects and values; a method's
    parameter values are the method's to check, and a list's items are the list's."""
    items = value.items() if isinstance(value, dict) else \
        enumerate(value) if place == ("runs",) else ()
    for key, sub in items:
        inner = (*place, key)
        name = f"{where}[{key}]" if isinstance(key, int) else \
            f"{where}.{key}" if where else key
        yield inner, name
        method_params = (len(inner) >= 3 and inner[-1] == "params" and inner[-3] == "series"
                         or len(inner) >= 2 and inner[-2] == "params")
        if not method_params:
            yield from _fields(sub, inner, name)


def test_every_field_of_a_written_sweep_json_is_type_checked(tmp_path):
    out = tmp_path / "S"
    out.mkdir()
    config = _config(tmp_path, methods=["noisy", "jbf"], params={"jbf": {"radius": 2}},
                     scene_params={"spp": "4"}, notes=["--scenes all leaves out ..."])
    stored = sweep_history.stored_config(out, config, None)
    sweep_history.RunRecord(out, stored, config, "local", 1, 0, 0).end(
        "interrupted", {"cells": 1, "failed": 1}, 0.5, error="KeyboardInterrupt: ")
    written = _stored(out)
    assert sweep_history.problem(written) == ""
    names = []
    for place, name in _fields(written):
        broken = json.loads(json.dumps(written))
        parent = broken
        for key in place[:-1]:
            parent = parent[key]
        # a list where anything else is expected, an object where a list is
        wrong = {} if isinstance(parent[place[-1]], list) else []
        parent[place[-1]] = wrong
        assert sweep_history.problem(broken).startswith(f"{name} is {json.dumps(wrong)}, not "), \
            name
        names.append(name)
    # what the checks cover: settings, series, the machine, and each run with its request
    assert {"config.params.jbf", "config.series.jbf[radius=2].params",
            "config.scene_labels.cornell", "config.scene_params.spp", "machine.packages.numpy",
            "config.scene_params_by_scene.cornell", "config.scene_params_by_scene.cornell.spp",
            "runs[0].notes", "runs[0].cells", "runs[0].failed", "runs[0].references_s", "runs[0].error",
            "runs[0].request.series.noisy.method", "runs[0].request.metrics"} <= set(names)


def test_the_results_sweep_files_are_readable():
    from pathlib import Path
    for path in Path(__file__).resolve().parents[2].glob("results/*/sweep.json"):
        assert sweep_history.problem(json.loads(path.read_text())) == "", path


@pytest.mark.mitsuba
def test_history_has_one_entry_per_run_and_marks_a_killed_one(renderer, tmp_path):
    out = tmp_path / "S"
    sweep.run_sweep(_config(tmp_path), out, progress=False)
    sweep.run_sweep(_config(tmp_path), out, progress=False)
    runs = _stored(out)["runs"]
    assert [(r["status"], r["cells"], r["reused"]) for r in runs] == [
        ("finished", 1, 0), ("finished", 0, 1)]
    for r in runs:
        assert r["started"] <= r["ended"] and r["request"]["spp"] == [2]
        assert r["request"]["ref_spp"] == 16 and "wall_s" in r
    # a run that never wrote its end (killed) is marked by the next one
    stored = _stored(out)
    stored["runs"][-1]["status"] = "running"
    (out / "sweep.json").write_text(json.dumps(stored))
    sweep.run_sweep(_config(tmp_path, spp=[4]), out, progress=False)
    runs = _stored(out)["runs"]
    assert [r["status"] for r in runs] == ["finished", "killed", "finished"]
    assert runs[-1]["cells"] == 1 and runs[-1]["request"]["spp"] == [4]
    assert _stored(out)["config"]["spp"] == [2, 4]


@pytest.mark.mitsuba
def test_rerun_compares_the_reference_spp_in_effect(renderer, tmp_path, monkeypatch):
    out = tmp_path / "S"
    monkeypatch.setenv("DBENCH_REF_SPP", "32")
    sweep.run_sweep(_config(tmp_path, ref_spp=16), out, progress=False)
    with pytest.raises(DbenchInputError, match=r"ref_spp: 16 there, 32 now\); use --rerun"):
        sweep.run_sweep(_config(tmp_path, ref_spp=None), out, progress=False)
    counts = sweep.run_sweep(_config(tmp_path, ref_spp=None, rerun=True), out, progress=False)
    assert counts["computed"] == 1
    config = _stored(out)["config"]
    assert config["ref_spp"] is None and config["ref_spp_default"] == 32
    assert sweep.load_cells(out)[0]["ref_spp"] == 32
    # the same reference asked for by its number is the same sweep
    again = sweep.run_sweep(_config(tmp_path, ref_spp=32), out, progress=False)
    assert again["computed"] == 0 and again["finished_before"] == 1
    monkeypatch.setenv("DBENCH_REF_SPP", "64")
    with pytest.raises(DbenchInputError, match=r"ref_spp: 32 there, 64 now"):
        sweep.run_sweep(_config(tmp_path, ref_spp=None), out, progress=False)


def test_a_transform_is_compared_by_what_each_scene_gets(tmp_path):
    # --transform box-cox is what a sweep without it gave its steady scenes: it resumes there
    out = tmp_path / "S"
    out.mkdir()
    stored = sweep_history.stored_config(out, _config(tmp_path), None)
    assert stored["config"]["transform"] is None
    again = sweep_history.stored_config(out, _config(tmp_path, transform="box-cox"), stored)
    assert again["config"]["transform"] is None  # the folder keeps what its cells used
    with pytest.raises(DbenchInputError, match="transform: None there, 'yeo-johnson' now"):
        sweep_history.stored_config(out, _config(tmp_path, transform="yeo-johnson"), stored)
    # a transient scene's default is identity: box-cox there is another result
    with pytest.raises(DbenchInputError, match="transform: None there, 'box-cox' now"):
        sweep_history.stored_config(
            out, _config(tmp_path, scenes=["cornell", "cornell-transient"], transform="box-cox"),
            stored)
    kept = sweep_history.stored_config(
        out, _config(tmp_path, scenes=["cornell-transient"], transform="identity"), stored)
    assert kept["config"]["transform"] is None


def test_each_scenes_own_values_are_recorded_and_kept_for_the_scenes_of_earlier_runs(tmp_path):
    # scene_params held the values given for every scene alone: a scene's own values (SCENE:
    # NAME=VALUE) were nowhere in the record, and a run extending the sweep with another scene
    # replaced the values the earlier scenes were rendered with
    out = tmp_path / "S"
    out.mkdir()
    first = _config(tmp_path, scenes=["cornell", "a.xml"], scene_params={"spp": "4"},
                    scene_params_by_scene={"a.xml": {"light": "5"}})
    stored = sweep_history.stored_config(out, first, None)
    assert stored["config"]["scene_params_by_scene"] == {
        "cornell": {"spp": "4"}, "a.xml": {"spp": "4", "light": "5"}}
    more = _config(tmp_path, scenes=["b.xml"], scene_params_by_scene={"b.xml": {"light": "7"}})
    again = sweep_history.stored_config(out, more, stored)["config"]
    assert again["scene_params_by_scene"] == {
        "cornell": {"spp": "4"}, "a.xml": {"spp": "4", "light": "5"}, "b.xml": {"light": "7"}}
    assert sweep_history.problem({"config": again}) == ""


def test_a_runs_notes_reach_the_report(tmp_path):
    from dbench.report.cells import run_notes_md

    out = tmp_path / "S"
    out.mkdir()
    said = "--scenes all leaves out these scene plugins: plugin lab-room (...) failed to load"
    for notes in ([], [said]):
        config = _config(tmp_path, notes=notes)
        stored = sweep_history.stored_config(out, config, sweep_history.read(out))
        sweep_history.RunRecord(out, stored, config, "local", 1, 0, 0).end(
            "finished", {"cells": 0, "failed": 0})
    runs = _stored(out)["runs"]
    assert "notes" not in runs[0] and runs[1]["notes"] == [said]
    assert "notes" not in _stored(out)["config"] and "notes" not in runs[1]["request"]
    assert run_notes_md(_stored(out)) == [
        "Notes of the runs:", "", f"- run 2 ({runs[1]['started']}): {said}", ""]
    assert run_notes_md({"runs": runs[:1]}) == []
