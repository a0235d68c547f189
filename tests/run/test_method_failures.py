"""A method that writes to its input, raises, or calls sys.exit: the harness names it, the other
methods get the pristine frame and finish, and ``dbench run`` exits with code 4
(dbench/run/inputs.py; issue: a user's plugin can never corrupt a verdict)."""
from __future__ import annotations

import json

import pytest

from dbench.synthetic import base_frame
from dbench.run.inputs import first_changed, private_copy
from dbench.cli import main

PLUGIN = '''
import numpy as np
from dbench.registry import Denoiser, register

@register("test-mutates")
class Mutates(Denoiser):
    kinds = {"steady"}
    needs = {"color"}
    def denoise(self, data):
        data.color *= 0
        data.color += 1
        return data.color

@register("test-torch-mutates")
class TorchMutates(Denoiser):
    kinds = {"steady"}
    needs = {"color"}
    def denoise(self, data):
        import torch, warnings
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            torch.from_numpy(data.color).mul_(0)
        return np.zeros_like(data.color)

@register("test-raises")
class Raises(Denoiser):
    kinds = {"steady"}
    needs = {"color"}
    def denoise(self, data):
        raise RuntimeError("plugin exploded")

@register("test-exits")
class Exits(Denoiser):
    kinds = {"steady"}
    needs = {"color"}
    def denoise(self, data):
        raise SystemExit(3)
'''


@pytest.fixture(scope="module")
def plugin(tmp_path_factory):
    path = tmp_path_factory.mktemp("plugins") / "bad_methods.py"
    path.write_text(PLUGIN)
    return path


def test_private_copy_is_read_only_and_compared():
    f = base_frame(5, 6)
    mine = private_copy(f)
    assert not mine.color.flags.writeable and not mine.stats.mean.flags.writeable
    with pytest.raises(ValueError, match="read-only"):
        mine.color[0, 0, 0] = 1
    assert first_changed(mine, f) is None
    mine.stats.mean.flags.writeable = True  # an owning copy: a determined method can do this
    mine.stats.mean[0, 0, 0] += 1
    assert first_changed(mine, f) == "stats.mean"


@pytest.mark.mitsuba
def test_run_names_failing_methods_and_keeps_the_others(plugin, tmp_path, capsys, renderer,
                                                        isolated):
    out = tmp_path / "run"
    code = main(["--plugin", str(plugin), "run", "--method",
                 "test-mutates,test-torch-mutates,test-raises,test-exits,noisy,jbf",
                 "--scene", "cornell", "--spp", "4", "--res", "16", "--ref-spp", "64",
                 "--quiet", "--out", str(out)])
    printed = capsys.readouterr()
    err = printed.err
    assert code == 4
    # each failed method is a row of the printed table, under the ranked ones
    assert "✗  test-raises  failed: plugin exploded" in printed.out or \
        "✗  test-raises  failed: RuntimeError: plugin exploded" in printed.out, printed.out
    assert "test-mutates: modified its input buffer color (wrote to a read-only" in err
    assert "test-torch-mutates: modified its input buffer color" in err
    assert "plugin exploded" in err and "sys.exit(3)" in err
    report = (out / "report.md").read_text(encoding="utf-8")
    assert "## Failed" in report and "test-raises" in report
    page = (out / "index.html").read_text(encoding="utf-8")  # the viewer names them too
    assert "<h2>Failed</h2>" in page and "plugin exploded" in page and "test-exits" in page
    import pandas as pd
    table = pd.read_csv(out / "metrics.csv")
    ok = table[table["status"] == "ok"]
    assert set(ok["method"]) == {"noisy", "jbf"}
    errors = table[table["status"] == "error"].set_index("method")
    assert set(errors.index) == {"test-mutates", "test-torch-mutates", "test-raises",
                                 "test-exits"}
    assert "plugin exploded" in errors.loc["test-raises", "error"]
    assert errors["rmse"].isna().all()  # no figures for a method that failed
    table = ok
    clean = main(["run", "--method", "noisy", "--scene", "cornell", "--spp", "4", "--res", "16",
                  "--ref-spp", "64", "--quiet", "--out", str(tmp_path / "clean")])
    assert clean == 0
    again = pd.read_csv(tmp_path / "clean" / "metrics.csv")
    assert table.set_index("method").loc["noisy", "rmse"] == pytest.approx(
        again.set_index("method").loc["noisy", "rmse"])
    assert json.loads((out / "run.json").read_text())["failed"]


@pytest.mark.parametrize("case", [c[0] for c in __import__(
    "dbench.stress.contract", fromlist=["CONTRACT_CASES"]).CONTRACT_CASES])
def test_stress_contract_cases(case):
    from dbench.stress.contract import run_contract_case
    outcome = run_contract_case(case)
    assert outcome.status == "pass", outcome.why


def test_a_failure_is_one_line_in_run_sweep_and_bench():
    # a message over two lines was two lines on dbench run's stderr and in the error cells
    # dbench sweep names (where sys.exit(3) was also 'SystemExit: 3', not run's words)
    from dbench.run import scene_run, sweep

    for module in (scene_run, sweep):
        assert module.method_failure(RuntimeError("no model\n  loaded")) == \
            "RuntimeError: no model loaded"
        assert module.method_failure(SystemExit(3)) == "called sys.exit(3) inside the method"
