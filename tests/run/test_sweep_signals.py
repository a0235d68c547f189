"""Ctrl-C stops a pool sweep (``--workers 2``) within seconds: groups not started are
cancelled, the workers end, finished cells are kept, the run is recorded as interrupted, and
the exit code is 130."""
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from dbench.run import sweep, sweep_lock

pytestmark = pytest.mark.mitsuba


def _cells(out: Path) -> list[Path]:
    return [p for p in out.glob("cells/*/*/*.json") if not p.name.startswith(".")]


def _session_processes(sid: int) -> list[int]:
    """Processes still alive in session ``sid`` (the sweep and its workers)."""
    alive = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[3]) == sid and fields[0] != "Z":  # session id; zombies are gone
            alive.append(int(stat.parent.name))
    return alive


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="needs /proc")
def test_ctrl_c_stops_a_pool_sweep_within_seconds(renderer, tmp_path):
    out = tmp_path / "S"
    spp = list(range(1, 61))  # 60 groups × 2 methods: long enough not to finish by itself
    cmd = [sys.executable, "-m", "dbench.cli", "sweep", "--methods", "noisy,jbf", "--scenes",
           "cornell", "--spp", ",".join(map(str, spp)), "--res", "8", "--ref-spp", "16",
           "--repeats", "1", "--workers", "2", "--out", str(out), "--quiet"]
    env = {**os.environ, "DBENCH_CACHE": str(tmp_path / "cache")}
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)
    try:
        deadline = time.time() + 120
        while time.time() < deadline and not _cells(out) and proc.poll() is None:
            time.sleep(0.02)
        assert _cells(out), "no cell was written"
        t_signal = time.time()
        os.killpg(proc.pid, signal.SIGINT)  # what Ctrl-C in a terminal does
        _, err = proc.communicate(timeout=30)
        stopped_s = time.time() - t_signal
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode == 130, err[-2000:]
    assert stopped_s < 10, stopped_s
    assert "dbench: interrupted" in err and "Traceback" not in err
    kept = _cells(out)
    assert 0 < len(kept) < len(spp)  # far fewer than the 120 planned
    assert len(sweep.load_cells(out)) == len(kept)  # every kept cell is whole
    time.sleep(0.5)
    assert _session_processes(proc.pid) == []  # no worker left behind
    assert not (out / sweep_lock.LOCK_NAME).exists()
    run = json.loads((out / "sweep.json").read_text())["runs"][-1]
    assert run["status"] == "interrupted" and run["cells"] <= len(kept)


def _sigterm_is_default() -> bool:
    return signal.getsignal(signal.SIGTERM) == signal.SIG_DFL


def test_a_pool_worker_ends_on_sigterm_without_a_traceback():
    # the workers are forked inside the command's signal handlers (dbench/cli), whose SIGTERM
    # handler raises; stop() ends them with SIGTERM, and an idle one printed a traceback
    from concurrent.futures import ProcessPoolExecutor
    from multiprocessing import get_context

    from dbench.report import run_output
    from dbench.run import sweep_pool

    with run_output.interrupts_flagged():
        with ProcessPoolExecutor(1, mp_context=get_context("fork"),
                                 initializer=sweep_pool.worker_start) as pool:
            assert pool.submit(_sigterm_is_default).result(timeout=60)
