"""The harness runs every method in the floating-point environment it found (bench/fpenv.py)."""
import platform
import subprocess
import sys

import pytest

from dbench.bench import fpenv

_CHILD = """
import sys
import numpy as np
from dbench import methods
from dbench.bench import fpenv
from dbench.bench.stress import base_frame

frame = base_frame()
nca = methods.get("nca")
if sys.argv[1] == "harness":
    fpenv.denoise(nca, frame)
else:
    nca.denoise(frame)
print(bool(np.float32(1e-40) * np.float32(1.0) != 0))  # a subnormal product survives
"""


def _subnormals_kept(way: str) -> bool:
    out = subprocess.run([sys.executable, "-c", _CHILD, way], capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout.split()[-1] == "True"


def test_a_method_that_sets_flush_to_zero_does_not_leak_it_through_the_harness():
    """ONNX Runtime's ``set_denormal_as_zero`` switches the calling thread to flush-to-zero when
    the process's first session is built and leaves it so: every later method in the process
    rounded subnormals to 0. Through :func:`fpenv.denoise` the thread gets its environment
    back. (Fresh processes: ONNX Runtime does it once per process.)"""
    assert _subnormals_kept("harness")
    assert not _subnormals_kept("bare")  # the leak the harness guards against is real


@pytest.mark.skipif(platform.machine() not in ("x86_64", "AMD64"),
                    reason="the rounding-mode constants are x86's")
def test_kept_fp_environment_restores_what_the_block_changed():
    assert fpenv.snapshot() is not None  # the C library has fegetenv
    towards_zero, nearest = 0xC00, 0
    with fpenv.kept_fp_environment():
        fpenv._LIBM.fesetround(towards_zero)
        assert fpenv._LIBM.fegetround() == towards_zero
    assert fpenv._LIBM.fegetround() == nearest
