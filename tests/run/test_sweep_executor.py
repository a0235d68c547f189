"""An executor a sweep cannot use is refused before the sweep writes or renders anything
(dbench/run/sweep_pool.py check_executor): ``--executor ray`` without Ray installed (an
optional dependency) rendered the references and wrote sweep.json, with a failed run, before
it ended as an internal error (exit 1), and ``run_sweep(executor="rays")`` ran locally."""
from __future__ import annotations

import sys

import pytest

from dbench import cli, datasets
from dbench.errors import DbenchInputError
from dbench.run import sweep


@pytest.fixture
def no_render(monkeypatch):
    def rendered(*a, **k):
        raise AssertionError("the sweep went past its checks")

    monkeypatch.setattr(datasets, "load", rendered)


def test_executor_ray_without_ray_is_refused_before_the_folder(no_render, tmp_path, capsys,
                                                               monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # as where it is not installed
    out = tmp_path / "x" / "sw"
    rc = cli.main(["sweep", "--methods", "noisy", "--scenes", "cornell", "--spp", "4",
                   "--res", "8", "--executor", "ray", "--quiet", "--cache",
                   str(tmp_path / "cache"), "--out", str(out)])
    err = capsys.readouterr().err
    assert rc == 2 and err == ("dbench: --executor ray: Ray is not installed here (pip install "
                               "'dbench[ray]'); install it, or use --executor local\n"), err
    assert not (tmp_path / "x").exists() and not (tmp_path / "cache").exists()


def test_an_unknown_executor_is_refused(no_render, tmp_path):
    config = sweep.SweepConfig(methods=["noisy"], scenes=["cornell"], spp=[4], res=8)
    with pytest.raises(DbenchInputError, match=r"^--executor: 'rays'; valid: local, ray$"):
        sweep.run_sweep(config, tmp_path / "sw", executor="rays", progress=False)
    assert not (tmp_path / "sw").exists()
