"""What a result records of the machine and the process (dbench/run/machine.py,
dbench/memory.py)."""
import numpy as np
from numpy._core import multiarray

from dbench import memory
from dbench.datasets.cache import Cache
from dbench.metrics.judge import judge
from dbench.report.formats import cores_text
from dbench.report.run_report import machine_md
from dbench.run import machine


def _advice() -> bool:
    """NumPy's huge-page advice now (read by setting it back to what it was)."""
    now = multiarray._set_madvise_hugepage(True)
    multiarray._set_madvise_hugepage(now)
    return bool(now)


def test_small_pages_inside_the_block_only_and_never_over_the_users_word(monkeypatch,
                                                                          tmp_path):
    before = multiarray._set_madvise_hugepage(True)
    try:
        monkeypatch.delenv("NUMPY_MADVISE_HUGEPAGE", raising=False)
        with memory.small_pages():
            assert _advice() is False
            with memory.small_pages():  # nested: back to the outer block's state
                assert _advice() is False
            assert _advice() is False
        assert _advice() is True
        # a cache read runs inside it (what it allocates is fresh arrays); the judge does not
        seen = []
        real = multiarray._set_madvise_hugepage
        monkeypatch.setattr(multiarray, "_set_madvise_hugepage",
                            lambda on: seen.append(on) or real(on))
        entry = Cache(tmp_path).put("k", {"a": 1}, arrays={"x": np.ones((2, 2, 3))})
        Cache(tmp_path).get("k", {"a": 1}).arrays()
        judge(np.ones((8, 8, 3), np.float32), np.ones((8, 8, 3), np.float32), names=["rmse"])
        assert seen == [False, True] and entry is not None
        line = memory.advice_text()
        assert "off while reading the cache" in line
        info = machine.machine_info()
        assert info["memory"] == line and f"- Memory: {line}" in machine_md(info)
        # the user's word stands throughout, and is what the report says
        seen.clear()
        monkeypatch.setenv("NUMPY_MADVISE_HUGEPAGE", "1")
        with memory.small_pages():
            assert _advice() is True
        Cache(tmp_path).get("k", {"a": 1}).arrays()
        assert [s for s in seen if s is False] == []
        assert memory.advice_text() == ("NumPy huge-page advice as NUMPY_MADVISE_HUGEPAGE=1 "
                                        "sets it, throughout")
    finally:
        multiarray._set_madvise_hugepage(before)


def _cgroup(monkeypatch, files: dict[str, str]) -> None:
    """The cgroup files ``machine`` reads: ``files`` (path -> text), every other one absent."""
    monkeypatch.setattr(machine, "_read", lambda path: files.get(path, ""))


def test_the_cores_a_process_may_use_are_recorded_not_only_the_machines(monkeypatch):
    monkeypatch.setattr(machine.os, "cpu_count", lambda: 16)
    monkeypatch.setattr(machine.os, "sched_getaffinity", lambda pid: {0, 1, 2, 3})
    _cgroup(monkeypatch, {})
    assert machine.usable_cores() == 4  # taskset / a cpuset: 4 of the 16
    assert machine.machine_label().endswith(", 4 of 16 cores")
    # a CPU quota (docker --cpus 2.5) allows 3 cores' time, rounded up; v2 and v1 forms
    _cgroup(monkeypatch, {machine._CPU_MAX: "250000 100000"})
    assert machine.usable_cores() == 3
    _cgroup(monkeypatch, {machine._CFS[0]: "150000", machine._CFS[1]: "100000"})
    assert machine.usable_cores() == 2
    for no_quota in ({machine._CPU_MAX: "max 100000"},
                     {machine._CFS[0]: "-1", machine._CFS[1]: "100000"}):
        _cgroup(monkeypatch, no_quota)
        assert machine.usable_cores() == 4
    info = {**machine.machine_info(), "cores": 16, "usable_cores": 4}
    assert "(4 of 16 cores)" in machine_md(info)  # worded as the label
    # all of them: the label and the report as before
    monkeypatch.setattr(machine.os, "sched_getaffinity", lambda pid: set(range(16)))
    _cgroup(monkeypatch, {})
    assert machine.machine_label().endswith(", 16 cores")
    assert "(16 cores)" in machine_md({**info, "usable_cores": 16})


def test_side_by_side_timing_names_the_usable_cores(monkeypatch):
    from dbench.report.cells import side_by_side_text
    from dbench.run.sweep_pool import side_by_side_line

    monkeypatch.setattr(machine.os, "cpu_count", lambda: 16)
    monkeypatch.setattr(machine.os, "sched_getaffinity", lambda pid: {0, 1})
    _cgroup(monkeypatch, {})
    assert "on 2 of 16 cores" in side_by_side_line("local", 2, 3)
    cell = {"status": "ok", "timed_beside": 1, "machine": machine.machine_label()}
    assert side_by_side_text([cell]) == ["timed with 2 workers side by side on 2 cores: "
                                         "time_s includes contention"]


def test_the_live_label_and_a_recorded_machine_word_the_cores_alike(monkeypatch):
    monkeypatch.setattr(machine.os, "cpu_count", lambda: 16)
    monkeypatch.setattr(machine.os, "sched_getaffinity", lambda pid: {0, 1, 2, 3})
    _cgroup(monkeypatch, {})
    live = machine.cores_text()
    assert live == cores_text(4, 16) == "4 of 16 cores"
    info = {**machine.machine_info(), "cores": 16, "usable_cores": 4}
    assert f"({live});" in machine_md(info)
    # a record made before usable_cores was kept, or without a count: what it has
    assert cores_text(None, 16) == cores_text(16, 16) == "16 cores"
    assert cores_text(2, None) == "2 cores" and cores_text(None, None) == "cores unknown"
    assert cores_text(True, 16) == "16 cores"  # a flag is no count
