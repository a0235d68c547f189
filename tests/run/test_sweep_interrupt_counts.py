"""An interrupted sweep records in sweep.json's history the cells it wrote before the interrupt
(``cells``, of them ``failed`` error cells), counted from the files it left, on a worker pool
as in one process, and is marked ``interrupted`` (dbench/run/sweep_history.py; README.md, the
``dbench sweep`` paragraph).

The cells are stand-ins: frames are not rendered and every method is "skipped" at once, except
jbf at one spp, which fails (an error cell), and jbf at another, where the interrupt arrives
after the group's noisy cell was written. Pool workers are forked, so they run the stand-ins
too."""
import json
from types import SimpleNamespace

import pytest

from dbench.run import harness, sweep

pytestmark = pytest.mark.mitsuba  # the plan fingerprints the scene (Mitsuba's dictionary)


def _stand_ins(monkeypatch, fail_spp: int, interrupt_spp: int) -> None:
    def load_seeds(scene, seed, n_seeds, spp, **kw):
        return [SimpleNamespace(kind="steady", meta={"spp": spp})]

    def run_cell(method, frames, **kw):
        spp = frames[0].meta["spp"]
        if method.name == "jbf" and spp == interrupt_spp:
            raise KeyboardInterrupt
        if method.name == "jbf" and spp == fail_spp:
            raise RuntimeError("stand-in failure")
        return harness.CellResult(method.name, dict(method.params), None, skipped="stand-in")

    monkeypatch.setattr(sweep, "load_seeds", load_seeds)
    # the stand-ins reach the pool's workers only in a fork (they start afresh otherwise:
    # tests/run/test_sweep_pool_start.py); what is tested here is the counting
    import multiprocessing

    from dbench.run import sweep_pool
    monkeypatch.setattr(sweep_pool, "_start_method", lambda: multiprocessing.get_context("fork"))
    monkeypatch.setattr(sweep, "render_references", lambda *a, **k: 0.0)
    monkeypatch.setattr(harness, "run_cell", run_cell)


def _written(out):
    cells = [json.loads(p.read_text()) for p in out.glob("cells/*/*/*.json")
             if not p.name.startswith(".")]
    return len(cells), sum(c["status"] == "error" for c in cells)


@pytest.mark.parametrize("workers, interrupt_spp", [(1, 3), (2, 4)])
def test_an_interrupted_sweep_records_the_cells_it_wrote(renderer, tmp_path, monkeypatch,
                                                         workers, interrupt_spp):
    _stand_ins(monkeypatch, fail_spp=2, interrupt_spp=interrupt_spp)
    config = sweep.SweepConfig(methods=["noisy", "jbf"], scenes=["cornell"], spp=[2, 3, 4, 5],
                               res=8, ref_spp=16, repeats=1, cache=str(tmp_path / "cache"))
    out = tmp_path / "S"
    with pytest.raises(KeyboardInterrupt):
        sweep.run_sweep(config, out, workers=workers, progress=False)
    cells, errors = _written(out)
    run = json.loads((out / "sweep.json").read_text())["runs"][-1]
    assert run["status"] == "interrupted" and "KeyboardInterrupt" in run["error"]
    # the interrupted group's first cell was written, though its result never came back
    assert cells >= (3 if workers == 1 else 1)
    assert run["cells"] == cells and run["reused"] == 0
    assert run["failed"] == errors
    if workers == 1:  # one process: the groups ran in order up to the interrupt
        assert (cells, errors) == (3, 1)

    # the next run computes the rest and the error cells again; its entry counts only those
    monkeypatch.setattr(harness, "run_cell", lambda method, frames, **kw: harness.CellResult(
        method.name, dict(method.params), None, skipped="stand-in"))
    counts = sweep.run_sweep(config, out, workers=workers, progress=False)
    again = json.loads((out / "sweep.json").read_text())["runs"][-1]
    kept = cells - errors
    assert counts["computed"] == 8 - kept == again["cells"] and again["status"] == "finished"
    assert again["reused"] == kept == counts["finished_before"] and again["failed"] == 0
