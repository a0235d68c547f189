"""The stress cases against every method's device path in its CPU-testable form
(dbench/bench/stress_device.py; docs/gpu.md §2): the same policy as the host paths."""
import pytest

from dbench.bench import stress, stress_device


@pytest.mark.parametrize("case", stress.CASES, ids=lambda c: c.name)
@pytest.mark.parametrize("method", stress_device.device_methods())
def test_device_form_stress_case(method, case):
    outcome = stress_device.run_device_case(method, case)
    assert outcome.status in ("pass", "n/a"), f"{method} [device] / {case.name}: {outcome.why}"


def test_device_forms_are_rows_of_the_matrix():
    res = stress.run_all(["nca"], progress=False)
    assert "nca" in res and "nca" + stress_device.SUFFIX in res
    assert "| nca [device form] |" in stress.stress_markdown(res)
