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
        "from dbench.datasets import render, mitsuba_env\n"
        "from dbench.datasets.scenes import catalogue as scenes\n"
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


def test_the_probe_verdict_is_kept_where_the_command_says(tmp_path, monkeypatch):
    """``--cache DIR`` keeps the renderer probe's verdict in DIR, ``--no-cache`` nowhere on disk
    (the CLI sets PROBE_STORE_ENV for the command), else beside the default cache."""
    from dbench.datasets import mitsuba_env as env

    monkeypatch.setenv("DBENCH_CACHE", str(tmp_path / "default"))
    monkeypatch.delenv(env.PROBE_STORE_ENV, raising=False)
    assert env._state_file() == tmp_path / "default" / "llvm_probe.json"
    monkeypatch.setenv(env.PROBE_STORE_ENV, str(tmp_path / "mine"))
    assert env._state_file("cuda") == tmp_path / "mine" / "cuda_probe.json"
    monkeypatch.setenv(env.PROBE_STORE_ENV, "none")
    assert env._state_file() is None
    ok, reason = env._probe("test", "print('ok')", "k", lambda code, last: f"{code} {last}")
    assert ok and reason == "" and not any(tmp_path.rglob("*_probe.json"))


def test_the_cli_sets_the_probe_store_for_the_command_only(tmp_path, monkeypatch):
    import os

    from dbench import cli
    from dbench.datasets import mitsuba_env as env

    monkeypatch.delenv(env.PROBE_STORE_ENV, raising=False)
    seen = {}

    def fake(args):
        seen["store"] = os.environ.get(env.PROBE_STORE_ENV)
        return 0
    monkeypatch.setattr(cli, "build_parser", _parser_with(fake))
    assert cli.main(["x", "--no-cache"]) == 0 and seen["store"] == "none"
    assert cli.main(["x", "--cache", str(tmp_path)]) == 0 and seen["store"] == str(tmp_path)
    assert env.PROBE_STORE_ENV not in os.environ


def _parser_with(func):
    import argparse

    def build():
        p = argparse.ArgumentParser()
        sub = p.add_subparsers()
        x = sub.add_parser("x")
        x.add_argument("--cache")
        x.add_argument("--no-cache", action="store_true")
        x.set_defaults(func=func, command="x")
        return p
    return build
