"""The render device (dbench/datasets/mitsuba_env.py): the CUDA check answers "no" quickly and
never takes the process down where no GPU is visible; ``choose_variant(device)``."""
import time

import pytest

from dbench.datasets import mitsuba_env
from dbench.errors import DbenchInputError, RendererUnavailableError


@pytest.fixture()
def fresh(monkeypatch, tmp_path):
    """No forced variant, a cache folder of its own, no remembered verdicts."""
    monkeypatch.delenv("DBENCH_VARIANT", raising=False)
    monkeypatch.delenv("DBENCH_RENDER_DEVICE", raising=False)
    monkeypatch.setenv("DBENCH_CACHE", str(tmp_path))
    for fn in (mitsuba_env.cuda_usable, mitsuba_env.choose_variant):
        fn.cache_clear()
    yield tmp_path
    for fn in (mitsuba_env.cuda_usable, mitsuba_env.choose_variant):
        fn.cache_clear()


def test_no_visible_driver_answers_no_at_once(fresh, monkeypatch):
    monkeypatch.setattr(mitsuba_env, "_NVIDIA_MARKERS", (str(fresh / "absent"),))
    t0 = time.perf_counter()
    ok, reason = mitsuba_env.cuda_usable()
    assert not ok and "no NVIDIA driver" in reason
    assert time.perf_counter() - t0 < 0.5
    assert not (fresh / "cuda_probe.json").exists()  # no child was started


def test_hidden_gpus_count_as_none(fresh, monkeypatch):
    marker = fresh / "version"
    marker.write_text("NVRM version: test\n")
    monkeypatch.setattr(mitsuba_env, "_NVIDIA_MARKERS", (str(marker),))
    monkeypatch.setenv("CUDA_VISIBLE_DEVICES", "-1")
    assert mitsuba_env.cuda_usable() == (False, "no NVIDIA driver visible")


def test_a_failing_cuda_check_is_a_verdict_not_a_crash(fresh, monkeypatch):
    # a driver seems visible but the child's render fails: "no", with the reason, remembered
    marker = fresh / "version"
    marker.write_text("NVRM version: test\n")
    monkeypatch.setattr(mitsuba_env, "_NVIDIA_MARKERS", (str(marker),))
    monkeypatch.delenv("CUDA_VISIBLE_DEVICES", raising=False)
    monkeypatch.setattr(mitsuba_env, "_CUDA_PROBE", "import os; os.abort()")
    ok, reason = mitsuba_env.cuda_usable()
    assert not ok and "CUDA test render failed" in reason
    assert (fresh / "cuda_probe.json").exists()
    mitsuba_env.cuda_usable.cache_clear()
    monkeypatch.setattr(mitsuba_env, "_CUDA_PROBE", "raise SystemExit(9)")
    assert mitsuba_env.cuda_usable() == (ok, reason)  # remembered: no second child


def test_choose_variant_by_device(fresh, monkeypatch):
    monkeypatch.setattr(mitsuba_env, "_NVIDIA_MARKERS", (str(fresh / "absent"),))
    cpu = mitsuba_env.choose_variant("cpu")
    assert cpu in (mitsuba_env.LLVM_VARIANT, mitsuba_env.SCALAR_VARIANT)
    assert mitsuba_env.choose_variant(None) == cpu  # no GPU: the default is the CPU's
    with pytest.raises(RendererUnavailableError, match="cannot render on cuda"):
        mitsuba_env.choose_variant("cuda")
    with pytest.raises(DbenchInputError, match="render device"):
        mitsuba_env.choose_variant("tpu")
    monkeypatch.setenv("DBENCH_VARIANT", "scalar_rgb")
    assert mitsuba_env.choose_variant("cuda") == "scalar_rgb"  # a forced variant wins


def test_the_variant_is_part_of_every_render_key():
    assert mitsuba_env.versions()["variant"] == mitsuba_env.current_variant()


def test_the_device_flag_chooses_the_render_device_for_the_command_only(monkeypatch):
    """``--device cpu`` reaches the variant choice through DBENCH_RENDER_DEVICE while the
    command runs (sweep workers inherit it), and the environment is as before afterwards."""
    import os

    from dbench import cli

    seen = {}

    def probe(args):
        seen["device"] = os.environ.get("DBENCH_RENDER_DEVICE")
        return 0

    monkeypatch.delenv("DBENCH_RENDER_DEVICE", raising=False)
    build = cli.build_parser
    monkeypatch.setattr(cli, "build_parser", lambda: _with_func(build(), probe))
    assert cli.main(["run", "--method", "noisy", "--scene", "cornell", "--device", "cpu"]) == 0
    assert seen["device"] == "cpu" and "DBENCH_RENDER_DEVICE" not in os.environ
    assert cli.main(["run", "--method", "noisy", "--scene", "cornell"]) == 0
    assert seen["device"] is None


def _with_func(parser, fn):
    """``parser`` whose every command runs ``fn``."""
    for action in parser._subparsers._group_actions:
        for sp in action.choices.values():
            sp.set_defaults(func=fn)
    return parser
