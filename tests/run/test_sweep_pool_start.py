"""A pool sweep's workers start afresh (dbench/run/sweep_pool.py ``_start_method``): forked
from a process in which PyTorch had already run a tensor operation, a worker's first such
operation waited forever (its OpenMP thread pool cannot run in a fork), so ``--workers 2``
hung in a notebook, a script or the test suite."""
import os
import subprocess
import sys

import pytest

CODE = """
import sys, torch
torch.set_num_threads(2)
torch.randn(256, 256) @ torch.randn(256, 256)  # PyTorch's thread pool runs in this process
from dbench import cli
sys.exit(cli.main(["sweep", "--methods", "noisy,jbf", "--scenes", "cornell", "--spp", "4,8",
                   "--res", "8", "--ref-spp", "16", "--repeats", "1", "--workers", "2",
                   "--quiet", "--cache", sys.argv[1] + "/cache", "--out", sys.argv[1] + "/S"]))
"""


@pytest.mark.mitsuba
def test_a_pool_sweep_started_after_pytorch_ran_finishes(renderer, tmp_path):
    proc = subprocess.run([sys.executable, "-c", CODE, str(tmp_path)], capture_output=True,
                          text=True, timeout=120, env={**os.environ})
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert len(list((tmp_path / "S" / "cells").rglob("*.json"))) == 4
