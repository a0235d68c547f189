"""What a result records of the machine and the process (dbench/run/machine.py,
dbench/memory.py)."""
import numpy as np
from numpy._core import multiarray

from dbench import memory
from dbench.datasets.cache import Cache
from dbench.metrics.judge import judge
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
