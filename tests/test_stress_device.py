"""The stress cases against every method's device path in its CPU-testable form
(dbench/bench/stress_device.py; docs/gpu.md §2): the same policy as the host paths.

The interpreter makes a case cost 0.1-3 s, so the default run covers the cases that reach each
kernel's distinct branches (non-finite, huge and tiny values, degenerate statistics, odd sizes,
rank-deficient and missing buffers); the whole matrix is marked slow (``scripts/test.sh -m
slow``) and runs in ``dbench stress``, which writes it to results/stress.md."""
import pytest

from dbench.bench import stress, stress_device

CORE = {"nan", "bright_3e38", "tiny_1e-20", "stats_n1", "size_1x1", "size_prime", "flat_wall",
        "missing_albedo", "missing_motion"}


def _cases():
    return [c if c.name in CORE else pytest.param(c, marks=pytest.mark.slow)
            for c in stress.CASES]


@pytest.mark.parametrize("case", _cases(), ids=lambda c: c.name)
@pytest.mark.parametrize("method", stress_device.device_methods())
def test_device_form_stress_case(method, case):
    outcome = stress_device.run_device_case(method, case)
    assert outcome.status in ("pass", "n/a"), f"{method} [device] / {case.name}: {outcome.why}"


def test_device_forms_are_rows_of_the_matrix():
    res = stress.run_all(["nca"], progress=False)
    res.update(stress_device.run_device_forms(["nca"], progress=False))
    assert "nca" in res and "nca" + stress_device.SUFFIX in res
    assert "| nca [device form] |" in stress.stress_markdown(res)
