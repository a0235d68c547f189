"""Comparing the verdicts of two references (dbench.report.refcompare)."""
import pandas as pd

from dbench.report import refcompare


def _frame(values, ci=0.01, ref=4096):
    return pd.DataFrame([{"scene": "s", "spp": 4, "method": m, "relmse": v, "relmse_ci": ci,
                          "ref_spp": ref} for m, v in values.items()])


def test_contradictions_changes_and_ratios():
    exp = _frame({"a": 0.10, "b": 0.20, "c": 0.30})
    cheap = _frame({"a": 0.25, "b": 0.205, "c": 0.31}, ref=1024)
    t = refcompare.compare(cheap, exp, metrics=("relmse",))
    row = t.iloc[0]
    # a<b under the expensive reference, a>b under the cheap one: a contradiction;
    # a<c stays; b<c stays (0.205 ± 0.01 vs 0.31 ± 0.01)
    assert row.pairs == 3 and row.contradictions == 1 and row.changes == 0
    assert row.flipped == "a/b" and row.max_ratio == 2.5
    tied = _frame({"a": 0.10, "b": 0.105, "c": 0.30}, ref=1024)
    t2 = refcompare.compare(tied, exp, metrics=("relmse",)).iloc[0]
    assert t2.contradictions == 0 and t2.changes == 1
