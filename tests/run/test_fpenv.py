"""The harness runs every method in the floating-point environment it found (run/fpenv.py),
and the shipped ONNX sessions leave it as they found it (methods/fpenv.py, ort_session.py)."""
import platform
import subprocess
import sys

import pytest

from dbench.run import fpenv

_CHILD = """
import sys
import numpy as np
from dbench import methods, registry
from dbench.run import fpenv
from dbench.synthetic import base_frame

frame = base_frame()
way, name = sys.argv[1], sys.argv[2]
if name == "flushing-plugin":  # a plug-in that switches its thread to flush-to-zero
    import torch
    from dbench.registry import Denoiser

    class Flushing(Denoiser):
        kinds = {"steady"}
        needs = {"color"}

        def denoise(self, data):
            torch.set_flush_denormal(True)
            return data.color

    method = Flushing()
else:
    method = registry.get(name)
if way == "harness":
    fpenv.denoise(method, frame)
else:
    method.denoise(frame)
print(bool(np.float32(1e-40) * np.float32(1.0) != 0))  # a subnormal product survives
"""


def _subnormals_kept(way: str, method: str) -> bool:
    out = subprocess.run([sys.executable, "-c", _CHILD, way, method], capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout.split()[-1] == "True"


def test_the_onnx_methods_leave_the_callers_environment_even_called_bare():
    """ONNX Runtime's ``set_denormal_as_zero`` switches the calling thread to flush-to-zero when
    the process's first session is built and leaves it so: every later method in the process
    rounded subnormals to 0, and so did a user's script after ``get("nca").denoise(...)``. The
    sessions are built and run inside the kept environment (ort_session.cpu_session). (Fresh
    processes: ONNX Runtime does it once per process.)"""
    assert _subnormals_kept("bare", "nca")
    assert _subnormals_kept("bare", "autoencoder")


def test_a_method_that_sets_flush_to_zero_does_not_leak_it_through_the_harness():
    """A plug-in that calls ``torch.set_flush_denormal(True)`` and leaves it so: through
    :func:`fpenv.denoise` the thread gets its environment back."""
    assert _subnormals_kept("harness", "flushing-plugin")
    assert not _subnormals_kept("bare", "flushing-plugin")  # the leak guarded against is real


@pytest.mark.skipif(platform.machine() not in ("x86_64", "AMD64"),
                    reason="the rounding-mode constants are x86's")
def test_kept_fp_environment_restores_what_the_block_changed():
    from dbench.methods.fpenv import _LIBM

    assert fpenv.snapshot() is not None  # the C library has fegetenv
    towards_zero, nearest = 0xC00, 0
    with fpenv.kept_fp_environment():
        _LIBM.fesetround(towards_zero)
        assert _LIBM.fegetround() == towards_zero
    assert _LIBM.fegetround() == nearest
