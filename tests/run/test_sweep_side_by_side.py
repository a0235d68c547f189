"""Cells timed side by side are said to be: ``dbench sweep --workers N`` runs its groups on N
processes at once, which render, judge and time on the same cores, so a cell's ``time_s``
includes that contention. Each cell records ``timed_beside`` (how many other groups could run
while it was timed; 0 with one worker), the sweep says so when it starts, and its summary, the
published README's settings line and the results page state it; a report of cells timed side
by side and alone says that their times do not compare (README.md, the ``dbench sweep``
paragraph). Nothing of it was recorded or said: the times stood unmarked beside those of a
sweep run with one worker."""
from __future__ import annotations

import pytest

from dbench import cli
from dbench.report import cells as report_cells, publish
from dbench.run import sweep, sweep_pool


def _sweep(tmp_path, out, workers: int, capsys) -> tuple[str, str]:
    rc = cli.main(["sweep", "--methods", "noisy,jbf", "--scenes", "cornell", "--spp", "4,8",
                   "--res", "8", "--ref-spp", "16", "--repeats", "1", "--workers",
                   str(workers), "--quiet", "--cache", str(tmp_path / "cache"),
                   "--out", str(out)])
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    return captured.out, captured.err


@pytest.mark.mitsuba
def test_a_pool_sweep_records_and_says_its_cells_were_timed_side_by_side(renderer, tmp_path,
                                                                         capsys):
    import os

    results = tmp_path / "results"
    out, err = _sweep(tmp_path, results / "sweep", 2, capsys)
    assert (f"dbench: warning: --workers 2: up to 2 cells are timed side by side on "
            f"{os.cpu_count()} cores; their time_s includes that contention and does not "
            "compare with a sweep's with --workers 1") in err
    cells = sweep.load_cells(results / "sweep")
    assert len(cells) == 4 and {c.get("timed_beside") for c in cells} == {1}
    said = (f"timed with 2 workers side by side on {os.cpu_count()} cores: time_s includes "
            "contention")
    assert f"warning: {said}" in out
    assert "timed_beside" not in cells[0]["identity"]  # the method's output does not change
    readme = publish.publish(results).read_text(encoding="utf-8")
    settings = next(line for line in readme.splitlines() if line.startswith("Sweep `sweep`"))
    assert said in settings
    assert said in (results / "index.html").read_text(encoding="utf-8")
    import pandas as pd

    table = pd.read_csv(results / "sweep" / "tables" / "cells.csv")
    assert set(table["timed_beside"]) == {1}


@pytest.mark.mitsuba
def test_a_one_worker_sweep_records_its_cells_timed_alone_and_says_nothing_new(
        renderer, tmp_path, capsys):
    results = tmp_path / "results"
    out, err = _sweep(tmp_path, results / "sweep", 1, capsys)
    assert "side by side" not in err + out and "contention" not in err + out
    assert {c.get("timed_beside") for c in sweep.load_cells(results / "sweep")} == {0}
    readme = publish.publish(results).read_text(encoding="utf-8")
    assert "side by side" not in readme.replace("times of different devices side by side", "")
    assert "contention" not in readme


def _cell(beside, machine="Some CPU, 2 cores", status="ok"):
    cell = {"status": status, "method": "jbf", "scene": "cornell", "spp": 4,
            "machine": machine}
    return cell if beside is None else {**cell, "timed_beside": beside}


def test_cells_timed_side_by_side_and_alone_are_said_not_to_compare():
    text = report_cells.side_by_side_text([_cell(1), _cell(1), _cell(0), _cell(None),
                                           _cell(0, status="error")], lambda s: f"**{s}**")
    assert text == ["timed alone (1 cell); with 2 workers side by side on 2 cores (2 cells); "
                    "not recorded (1 cell) (**times measured side by side and alone do not "
                    "compare: time_s includes contention where timed side by side**)"]
    assert report_cells.side_by_side_text([_cell(0), _cell(None)]) == []
    assert report_cells.side_by_side_text([_cell(3, machine="?")]) == [
        "timed with 4 workers side by side: time_s includes contention"]


def test_what_the_sweep_says_at_its_start():
    assert sweep_pool.side_by_side_line("local", 1, 5) == ""
    assert sweep_pool.side_by_side_line("local", 4, 1) == ""  # one group: timed alone
    assert "up to 2 cells are timed side by side" in sweep_pool.side_by_side_line("local", 4, 2)
    assert "--executor ray: a node runs as many cells at once as it has CPUs" in \
        sweep_pool.side_by_side_line("ray", 1, 3)


def test_a_ray_task_counts_the_tasks_its_node_runs_beside_it(monkeypatch):
    ray = pytest.importorskip("ray")

    class Context:
        def get_node_id(self):
            return "b"

    monkeypatch.setattr(ray, "get_runtime_context", lambda: Context())
    monkeypatch.setattr(ray, "nodes", lambda: [{"NodeID": "a", "Resources": {"CPU": 64.0}},
                                               {"NodeID": "b", "Resources": {"CPU": 4.0}}])
    assert sweep_pool.ray_beside(10) == 3
    assert sweep_pool.ray_beside(1) == 1  # two groups in all: one beside at most
    assert sweep_pool.ray_beside(0) == 0
