"""Scoring one output: the judge against the reference its frame carries (shared by the cell
harness and the sequence runner)."""
from __future__ import annotations

from typing import Sequence

import numpy as np

from ..metrics import judge, records

#: The metrics a cell scores by default: every metric the judge scores (the metric records
#: with a surface form).
DEFAULT_METRICS = records.judged()


def judge_frame(output: np.ndarray, frame, names: Sequence[str] = DEFAULT_METRICS):
    """:func:`dbench.metrics.judge.judge` of ``output`` against ``frame``'s reference, surface
    (emitter fraction 0) and reference variance, when the frame carries them."""
    return judge.judge(output, frame.reference, emitter=getattr(frame, "emitter", None),
                       reference_var=getattr(frame, "reference_var", None),
                       ev=frame.meta.get("ev", 0.0),
                       names=[n for n in names if n in judge.JUDGED])
