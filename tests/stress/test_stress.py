"""The stress cases of `dbench stress`, run for every registered method (issue: benchmark suite)."""
import numpy as np
import pytest

from dbench import registry
from dbench.stress import cases, runner
from dbench.synthetic import base_frame


@pytest.mark.parametrize("case", cases.CASES, ids=lambda c: c.name)
@pytest.mark.parametrize("method", registry.available()
                         + ["statistical+gate", "jbf+gate", "nca+gate"])
def test_stress_case(method, case):
    outcome = runner.run_case(method, case)
    assert outcome.status in ("pass", "n/a"), f"{method} / {case.name}: {outcome.why}"


def test_judge_detects_spread_and_shape():
    import numpy as np
    frame = base_frame(6, 6)
    out = np.array(frame.color, copy=True)
    out[0, 0] = np.nan
    assert runner._judge(frame, out, 0.0).status == "fail"
    assert runner._judge(frame, out[:5], 0.0).status == "fail"
    assert runner._judge(frame, frame.color.astype(np.float64), 0.0).status == "fail"
    assert runner._judge(frame, frame.color, 0.0).status == "pass"


def test_markdown_matrix_lists_every_method_and_case():
    res = runner.run_all(["noisy"], progress=False)
    text = runner.stress_markdown(res)
    assert "| noisy |" in text and all(c.name in text for c in cases.CASES)
    assert all(c.expect in text for c in cases.CASES)


# --- one huge finite pixel, missing depth (tiny 16×16 frames) -------------

def _bright_frame(value, sequence):
    import numpy as np
    f = base_frame(16, 16)
    c = f.color.copy()
    c[5, 7] = value
    f = cases._with_color(f, c)
    if sequence:
        f = f.with_buffers(motion=np.zeros((16, 16, 2), np.float32), gradient=f.color.copy())
    return f


_IMAGE_METHODS = [m for m in registry.available()
                  if registry.get(m).kinds & {"steady", "sequence"}]


@pytest.mark.parametrize("value", [5e18, 1e30, 3e38])
@pytest.mark.parametrize("method", _IMAGE_METHODS)
def test_one_huge_finite_pixel_stays_finite(method, value):
    """One pixel at 5e18 / 1e30 / 3e38 used to turn whole frames NaN (svgf/asvgf: float32
    moments l² overflowed in the first frame's spatial variance; bmfr and the autoencoder at
    3e38: demodulation / log1p(color / a) overflowed). First AND second frame after reset()."""
    import numpy as np
    m = registry.get(method)
    seq = "sequence" in m.kinds
    frame = _bright_frame(value, seq)
    m.reset()
    outs = [m.denoise(frame)]
    if seq:
        outs.append(m.denoise(frame))
    for i, out in enumerate(outs):
        assert out.shape == frame.color.shape and out.dtype == np.float32
        bad = int((~np.isfinite(out)).any(-1).sum())
        assert bad == 0, f"{method}: {bad} non-finite pixels on frame {i + 1} at {value:g}"


@pytest.mark.parametrize("method", ["jbf", "statistical", "statistical+gate", "jbf+gate"])
def test_missing_depth_runs_with_the_hit_mask_from_normals(method):
    """Depth is optional (renders from files lack it): without it the output is finite and
    equals the run with a depth that is 1 where the normal is non-zero."""
    import numpy as np
    frame = base_frame(16, 16)
    hit = np.any(frame.normal != 0, axis=-1, keepdims=True).astype(np.float32)
    out = registry.get(method).denoise(frame.with_buffers(depth=None))
    assert np.isfinite(out).all()
    np.testing.assert_array_equal(out, registry.get(method).denoise(frame.with_buffers(depth=hit)))


def test_jbf_illumination_huge_pixel_matches_reference():
    """The power-of-two plane scaling keeps the fast illumination filter finite and equal to
    the float64 reference for colours whose demodulated value overflows float32."""
    import numpy as np
    f = _bright_frame(3e38, False)
    fast = registry.get("jbf", mode="illumination", radius=3).denoise(f)
    ref = registry.get("jbf", mode="illumination", radius=3, backend="reference").denoise(f)
    assert np.isfinite(fast).all()
    np.testing.assert_allclose(fast, ref, rtol=1e-4, atol=1e-6)


def test_clamp_magnitude_keeps_ordinary_and_missing_values():
    import numpy as np
    from dbench.methods.guards import RADIANCE_MAX, clamp_magnitude
    x = np.array([0.5, -2.0, 1e16, -3e38, np.nan, np.inf, -np.inf], np.float32)
    y = clamp_magnitude(x)
    assert y[0] == 0.5 and y[1] == -2.0 and y[2] == np.float32(RADIANCE_MAX)
    assert y[3] == -np.float32(RADIANCE_MAX) and np.isnan(y[4]) and y[5] == np.inf
    assert y[6] == -np.inf
    ordinary = np.linspace(-10, 10, 7, dtype=np.float32)
    assert clamp_magnitude(ordinary) is ordinary


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_compiled_clamp_equals_clamp_magnitude(dtype):
    """temporal.clamp_radiance (the sequence methods' input guard) equals guards.clamp_magnitude
    bit for bit: the input itself when nothing exceeds the limit, the same clamped copy
    otherwise (limits at float32 rounding, NaN and ±Inf kept, non-contiguous input too)."""
    from dbench.methods.guards import RADIANCE_MAX, clamp_magnitude
    from dbench.methods.temporal import clamp_radiance

    rng = np.random.default_rng(3)
    x = rng.standard_normal((37, 41, 3)).astype(dtype) * 1e3
    assert clamp_radiance(x, RADIANCE_MAX) is x
    for value in (1e16, -3e38 if dtype == np.float32 else -1e300, np.nan, np.inf, -np.inf,
                  np.float32(RADIANCE_MAX), np.nextafter(dtype(RADIANCE_MAX), dtype(np.inf))):
        y = x.copy()
        y[5, 7, 1] = value
        y[30, 2, 0] = -abs(value) if np.isfinite(value) else value
        want, got = clamp_magnitude(y, RADIANCE_MAX), clamp_radiance(y, RADIANCE_MAX)
        np.testing.assert_array_equal(got, want)
        assert (got is y) == (want is y)
    strided = x[:, ::2]
    np.testing.assert_array_equal(clamp_radiance(strided, 1.0), clamp_magnitude(strided, 1.0))


def test_quiet_stress_prints_no_library_warnings(tmp_path, capfd, monkeypatch):
    """The hostile inputs make NumPy and Triton's interpreter warn (here: a NumPy warning
    raised inside the matrix); under --quiet the matrix is printed with a count of them, not
    the warnings themselves."""
    from dbench.cli import main

    run_all = runner.run_all

    def warning_run_all(*args, **kwargs):
        np.log(np.zeros(2))  # RuntimeWarning: divide by zero, as a NaN/Inf case raises
        return run_all(*args, **kwargs)

    monkeypatch.setattr(runner, "run_all", warning_run_all)
    assert main(["stress", "--methods", "jbf", "--quiet", "--out", str(tmp_path)]) == 0
    captured = capfd.readouterr()
    assert "Warning" not in captured.err + captured.out
    assert "on the hostile inputs: " in captured.out  # counted, and kept beside stress.md
    assert f"see {tmp_path / 'stress.log'}" in captured.out
    assert "RuntimeWarning" in (tmp_path / "stress.log").read_text(encoding="utf-8")
    assert (tmp_path / "stress.md").exists()


def test_a_plugin_writing_to_its_input_or_exiting_fails_its_cases(isolated):
    """The stress matrix gives each method a read-only copy, as a run does: a method that
    writes to its input, or calls sys.exit, fails the case with the reason."""
    from dbench.denoiser import Denoiser, register

    @register("stress-mutates")
    class Mutates(Denoiser):
        kinds, needs = {"steady"}, {"color"}

        def denoise(self, data):
            data.color *= 0
            return np.zeros_like(data.color)

    @register("stress-exits")
    class Exits(Denoiser):
        kinds, needs = {"steady"}, {"color"}

        def denoise(self, data):
            raise SystemExit(3)

    case = next(c for c in runner.CASES if c.kind != "transient" and not c.error_ok)
    mutated = runner.run_case("stress-mutates", case)
    assert mutated.status == "fail" and "modified its input" in mutated.why, mutated
    exited = runner.run_case("stress-exits", case)
    assert exited.status == "fail" and "sys.exit(3)" in exited.why, exited


def test_the_readme_counts_the_cases():
    from pathlib import Path

    readme = " ".join((Path(__file__).parents[2] / "README.md").read_text().split())
    assert f"{len(cases.CASES)} adversarial inputs" in readme


def test_a_slow_first_call_is_timed_again_and_a_slow_method_still_fails(monkeypatch):
    # the first call in a process compiles a method's kernels: on a loaded machine that alone
    # passed the limit and failed a case whose input costs nothing; a method slow on every
    # call still fails
    import time

    from dbench.stress.cases import CASES

    monkeypatch.setattr(runner, "TIME_LIMIT_S", 0.05)
    frame = base_frame(6, 6)

    class Stub:
        needs = {"color"}

        def __init__(self, slow_calls):
            self.slow_calls = slow_calls

        def reset(self):
            pass

    def call_of(stub):
        def call(f):
            if stub.slow_calls:
                stub.slow_calls -= 1
                time.sleep(0.1)
            return np.array(f.color, copy=True)
        return call

    case = CASES[0]
    once = Stub(slow_calls=1)
    assert runner.judged_calls(once, case, frame, False, call_of(once)).status == "pass"
    always = Stub(slow_calls=10)
    outcome = runner.judged_calls(always, case, frame, False, call_of(always))
    assert outcome.status == "fail" and outcome.why.startswith("took")
