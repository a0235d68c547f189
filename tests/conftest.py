"""Shared fixtures. Rendering tests use tiny images and a small reference spp."""
from __future__ import annotations

import os
import sys

import pytest

os.environ.setdefault("DBENCH_REF_SPP", "256")

from dbench.run import fpenv  # noqa: E402

#: the floating-point environment the test process started with (no flush-to-zero)
_PRISTINE_FP = fpenv.snapshot()


@pytest.fixture(autouse=True, scope="session")
def _ctrl_c_as_at_a_terminal():
    """Ctrl-C (SIGINT) raises KeyboardInterrupt, as in a terminal, also where the suite was
    started as a shell's background job (``cmd &``), which starts it ignoring SIGINT: the tests
    of interrupts, and the processes they start, would otherwise never see one."""
    import signal

    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    yield


@pytest.fixture(autouse=True)
def _pristine_fp_environment():
    """Every test starts in the process's initial floating-point environment: a test that
    builds an ONNX Runtime session directly (``nca``, ``autoencoder``) leaves flush-to-zero
    set on the thread, which would hide subnormal cases from the tests after it."""
    fpenv.restore(_PRISTINE_FP)
    yield


def _renderer_ok() -> tuple[bool, str]:
    try:
        from dbench.datasets.mitsuba_env import mitsuba
        mitsuba()
        return True, ""
    except Exception as exc:  # noqa: BLE001
        return False, str(exc)


@pytest.fixture(scope="session")
def renderer():
    ok, why = _renderer_ok()
    if not ok:
        pytest.skip(f"Mitsuba unavailable: {why}")
    from dbench.datasets.mitsuba_env import mitsuba
    return mitsuba()


@pytest.fixture(scope="module")
def tr(renderer):
    """dbench.datasets.transient.load with mitransient imported (transient tests; needs LLVM)."""
    from dbench.datasets import mitsuba_env
    if not mitsuba_env.mitsuba().variant().startswith(("llvm", "cuda")):
        pytest.skip("transient rendering needs the llvm_ad_rgb variant")
    from dbench.datasets.transient import load as transient
    transient._mitransient()
    return transient


@pytest.fixture()
def tmp_cache(tmp_path):
    from dbench.datasets import Cache
    return Cache(tmp_path / "cache")


@pytest.fixture()
def isolated():
    """Restore the method and scene registries, the plugin records, sys.modules and sys.path
    after a test that loads plugins (tests/test_plugins.py, tests/cli/test_exit_codes.py)."""
    import dbench.methods  # noqa: F401 - built-ins in the snapshot
    from dbench import plugins, registry
    from dbench.datasets.scenes import catalogue as scenes, record

    plugins.ensure_loaded()
    methods_before = dict(registry._REGISTRY)
    scenes_before = dict(scenes._CATALOGUE)
    not_loaded_before = dict(record._NOT_LOADED)
    plugins_before = dict(plugins._PLUGINS)
    requested_before = list(plugins._REQUESTED)
    state_before = dict(plugins._STATE)
    modules_before = set(sys.modules)
    path_before = list(sys.path)
    yield
    registry._REGISTRY.clear()
    registry._REGISTRY.update(methods_before)
    scenes._CATALOGUE.clear()
    scenes._CATALOGUE.update(scenes_before)
    record._NOT_LOADED.clear()
    record._NOT_LOADED.update(not_loaded_before)
    plugins._PLUGINS.clear()
    plugins._PLUGINS.update(plugins_before)
    plugins._REQUESTED[:] = requested_before
    plugins._STATE.update(state_before)
    for name in set(sys.modules) - modules_before:
        if name.startswith(("dbench_plugin_", "dbench_example_plugin", "tiny_scene_plugin")):
            del sys.modules[name]
    sys.path[:] = path_before
