"""Variant choice never takes the process down; scalar fallback works (docs/mitsuba.md §10)."""
import os
import subprocess
import sys

import pytest

from dbench.datasets import mitsuba_env


def test_probe_answers_without_crashing():
    ok, reason = mitsuba_env.llvm_usable()
    assert isinstance(ok, bool) and (ok or "libllvm19" in reason)


@pytest.mark.mitsuba
def test_scalar_fallback_renders_and_refuses_transient(tmp_path):
    code = (
        "import numpy as np\n"
        "from dbench.datasets import render, scenes, mitsuba_env\n"
        "from dbench.errors import RendererUnavailableError\n"
        "assert mitsuba_env.mitsuba().variant() == 'scalar_rgb'\n"
        "c, st, _ = render.render_passes(scenes.get('cornell'), 8, 2, stats=('box-cox', 0.5),"
        " progress=False)\n"
        "assert np.isfinite(c).all() and c.max() > 0\n"
        "try:\n"
        "    mitsuba_env.require_llvm('transient rendering')\n"
        "except RendererUnavailableError as e:\n"
        "    assert 'transient rendering needs' in str(e); print('refused')\n")
    env = {**os.environ, "DBENCH_VARIANT": "scalar_rgb", "DBENCH_CACHE": str(tmp_path)}
    proc = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "refused" in proc.stdout
