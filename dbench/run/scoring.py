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
    (emitter fraction 0; a folder's frame without an emitter buffer: not its
    ``judged_lights``) and reference variance, when the frame carries them."""
    lights = getattr(frame, "emitter", None)
    if lights is None:
        lights = getattr(frame, "judged_lights", None)
    return judge.judge(output, frame.reference, emitter=lights,
                       reference_var=getattr(frame, "reference_var", None),
                       ev=frame.meta.get("ev", 0.0),
                       names=[n for n in names if n in judge.JUDGED])
