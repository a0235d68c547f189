"""The stress cases against every method's device path in its CPU-testable form
(dbench/stress/device.py; docs/gpu.md §2): the same policy as the host paths.

The interpreter makes a case cost 0.1-3 s, so the default run covers the cases that reach each
kernel's distinct branches (non-finite, huge and tiny values, degenerate statistics, odd sizes,
rank-deficient and missing buffers); the whole matrix is marked slow (``scripts/test.sh -m
slow``) and runs in ``dbench stress``, which writes it to results/stress.md."""
import pytest

from dbench.stress import cases, device as stress_device, runner

CORE = {"nan", "bright_3e38", "tiny_1e-20", "stats_n1", "size_1x1", "size_prime", "flat_wall",
        "missing_albedo", "missing_motion"}
#: the temporal device forms take 2-6 s a case through the interpreter (their own test files
#: cover their hostile inputs frame by frame): three cases each in the default run
TEMPORAL_CORE = {"nan", "bright_3e38", "missing_motion"}
SLOW_FORMS = {"svgf", "asvgf", "bmfr"}


def _pairs():
    out = []
    for m in stress_device.device_methods():
        core = TEMPORAL_CORE if m in SLOW_FORMS else CORE
        out += [pytest.param(m, c, id=f"{m}-{c.name}",
                             marks=() if c.name in core else pytest.mark.slow)
                for c in cases.CASES]
    return out


@pytest.mark.parametrize("method, case", _pairs())
def test_device_form_stress_case(method, case):
    outcome = stress_device.run_device_case(method, case)
    assert outcome.status in ("pass", "n/a"), f"{method} [device] / {case.name}: {outcome.why}"


def test_device_forms_are_rows_of_the_matrix():
    res = runner.run_all(["nca"], progress=False)
    res.update(stress_device.run_device_forms(["nca"], progress=False))
    assert "nca" in res and "nca" + stress_device.SUFFIX in res
    assert "| nca [device form] |" in runner.stress_markdown(res)
