"""First calls in fresh processes (dbench/speed/timing.py, ``first_call_times``): what
``dbench bench render`` adds to its warm rounds for a transient scene."""
from __future__ import annotations

import pytest

from dbench.speed.timing import first_call_times


def test_each_way_runs_in_its_own_process_in_abba_order(tmp_path, monkeypatch):
    """Each way's call is timed in a process of its own, the order reversed every other round;
    the child builds the call from the keyword arguments (here: a stand-in module that
    records its process and order in files)."""
    (tmp_path / "standin_first.py").write_text(
        "import os, pathlib\n"
        "def build(way, folder):\n"
        "    def call():\n"
        "        n = len(list(pathlib.Path(folder).iterdir()))\n"
        "        pathlib.Path(folder, f'{n:02d}-{way}-{os.getpid()}').touch()\n"
        "    return call\n")
    calls = tmp_path / "calls"
    calls.mkdir()
    monkeypatch.setenv("PYTHONPATH", str(tmp_path))
    times = first_call_times("standin_first:build", ["a", "b"], {"folder": str(calls)}, 3)
    assert {w: len(t) for w, t in times.items()} == {"a": 3, "b": 3}
    assert all(t >= 0 for ts in times.values() for t in ts)
    names = sorted(p.name for p in calls.iterdir())
    assert [n.split("-")[1] for n in names] == ["a", "b", "b", "a", "a", "b"]
    assert len({n.split("-")[2] for n in names}) == 6  # six processes


def test_a_failing_child_is_named_in_one_line(tmp_path):
    with pytest.raises(RuntimeError, match=r"first call of 'plain' in a fresh process failed "
                                           r"\(exit 1\): .*no-such-scene"):
        first_call_times("dbench.speed.transient_render:first_call", ["plain"],
                         dict(scene="no-such-scene", res=8, spp=1, bins=8,
                              transform="identity", lam=0.5, cache_root=str(tmp_path)), 1)
