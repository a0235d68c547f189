"""The stress cases of `dbench stress`, run for every registered method (issue: benchmark suite)."""
import pytest

from dbench import methods
from dbench.bench import stress


@pytest.mark.parametrize("case", stress.CASES, ids=lambda c: c.name)
@pytest.mark.parametrize("method", methods.available())
def test_stress_case(method, case):
    outcome = stress.run_case(method, case)
    assert outcome.status in ("pass", "n/a"), f"{method} / {case.name}: {outcome.why}"


def test_judge_detects_spread_and_shape():
    import numpy as np
    frame = stress.base_frame(6, 6)
    out = np.array(frame.color, copy=True)
    out[0, 0] = np.nan
    assert stress._judge(frame, out, 0.0).status == "fail"
    assert stress._judge(frame, out[:5], 0.0).status == "fail"
    assert stress._judge(frame, frame.color.astype(np.float64), 0.0).status == "fail"
    assert stress._judge(frame, frame.color, 0.0).status == "pass"


def test_markdown_matrix_lists_every_method_and_case():
    res = stress.run_all(["noisy"], progress=False)
    text = stress.stress_markdown(res)
    assert "| noisy |" in text and all(c.name in text for c in stress.CASES)
