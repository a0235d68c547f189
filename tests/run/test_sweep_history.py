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
    ('{"config": {"spp": [2]}, "runs": {}}', "runs is not a list"),
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
