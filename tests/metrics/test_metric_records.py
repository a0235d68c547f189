"""One record per metric (dbench/metrics/records.py): every name any module uses has a record,
the directions, ``--rank-by`` choices, headline columns and printed definitions are read from
the records (a throwaway record reaches all of them), and the records' per-pixel maps are the
judge's to the last bit."""
from __future__ import annotations

import numpy as np
import pytest

from dbench import metrics
from dbench.cli import args
from dbench.errors import DbenchInputError
from dbench.learn import evaluate
from dbench.metrics import judge as J
from dbench.metrics import records
from dbench.metrics.pixel import _err_sq
from dbench.metrics.records import METRICS, Metric
from dbench.report import publish, refcompare, run_report, tables, verdicts
from dbench.run import scoring


def _used_lists() -> dict[str, tuple[str, ...]]:
    """Every list of metric names a module keeps (``time_s`` is a time column, no metric)."""
    lists = {
        "scoring.DEFAULT_METRICS": scoring.DEFAULT_METRICS,
        "verdicts.METRICS": verdicts.METRICS,
        "verdicts.HIGHER_IS_BETTER": tuple(verdicts.HIGHER_IS_BETTER),
        "verdicts.HEADLINE": verdicts.HEADLINE,
        "args.RANKABLE": tuple(args.RANKABLE),
        "evaluate.METRICS": evaluate.METRICS,
        "publish.SEQUENCE_HEADLINE": publish.SEQUENCE_HEADLINE,
        "publish.TRANSIENT_HEADLINE": publish.TRANSIENT_HEADLINE,
        "publish.README_CONVERGENCE": publish.README_CONVERGENCE,
        "run_report.SEQUENCE_COLUMNS": run_report.SEQUENCE_COLUMNS,
        "refcompare.METRICS": refcompare.METRICS,
        "tables.COLUMNS": tables.COLUMNS,
        "tables.TEMPORAL": tables.TEMPORAL,
        "tables.EQUAL_TIME_METRICS": tables.EQUAL_TIME_METRICS,
        "judge.JUDGED": J.JUDGED,
        "judge.metric_names": tuple(J.metric_names()),
        "metrics.available": tuple(metrics.available()),
        "metrics.DEFINITIONS": tuple(metrics.DEFINITIONS),
        "metrics.HIGHER_IS_BETTER": tuple(metrics.HIGHER_IS_BETTER),
        "metrics.PER_BIN_METRICS": metrics.PER_BIN_METRICS,
    }
    return {k: tuple(n for n in v if n != verdicts.TIME) for k, v in lists.items()}


def test_every_metric_name_in_use_has_a_record():
    for where, names in _used_lists().items():
        missing = [n for n in names if n not in METRICS]
        assert not missing, f"{where}: {missing} have no record in dbench/metrics/records.py"
    for cols in (verdicts.HEADLINE, publish.SEQUENCE_HEADLINE, publish.TRANSIENT_HEADLINE):
        assert cols[-1] == verdicts.TIME and verdicts.TIME not in METRICS


def test_records_are_consistent():
    for name, m in METRICS.items():
        assert m.name == name and m.kind in records.KINDS and m.domain in ("hdr", "ldr")
        assert m.range[0] < m.range[1]
        assert m.definition is None or (m.definition and "\n" not in m.definition)
        if m.variant is not None:
            base = METRICS[m.variant_of]
            assert m.variant in records.VARIANTS and base.variant is None
            assert (m.higher_is_better, m.range, m.domain) == (
                base.higher_is_better, base.range, base.domain) or m.variant == "share"
    for name in records.image_metrics():
        assert METRICS[name].definition, name  # every metric compute knows is defined
    for name in records.judged():
        assert f"{name}_surface" in METRICS and METRICS[name].per_pixel_map is not None
    # derived forms follow their base metric's flags
    assert {n for n, m in METRICS.items() if m.variant == "surface"} == {
        f"{n}_surface" for n, m in METRICS.items() if m.has_surface_variant}
    assert {n for n, m in METRICS.items() if m.variant == "unbiased"} == {
        f"{n}_unbiased" for n, m in METRICS.items() if m.has_unbiased_variant}


def test_directions_choices_lists_and_definitions_come_from_the_records():
    hib = {n for n, m in METRICS.items() if m.higher_is_better}
    assert verdicts.HIGHER_IS_BETTER == hib == metrics.HIGHER_IS_BETTER
    for name in METRICS:
        assert verdicts.higher_is_better(name) == metrics.higher_is_better(name) == (name in hib)
    assert not verdicts.higher_is_better(verdicts.TIME)
    assert tuple(args.RANKABLE) == args.rankable() == tuple(
        n for n in records._grouped() if METRICS[n].rankable)
    assert scoring.DEFAULT_METRICS == J.JUDGED == tuple(
        n for n, m in METRICS.items() if m.has_surface_variant)
    assert verdicts.METRICS == tables.COLUMNS == tuple(J.metric_names()) + tables.TEMPORAL
    assert tables.TEMPORAL == tuple(n for n, m in METRICS.items() if m.kind != "image")
    assert metrics.DEFINITIONS == {n: METRICS[n].definition for n in metrics.available()}
    for run, cols in (("steady", verdicts.HEADLINE), ("sequence", publish.SEQUENCE_HEADLINE),
                      ("transient", publish.TRANSIENT_HEADLINE)):
        assert cols[:-1] == tuple(n for n in records._grouped() if run in METRICS[n].headline)
    assert run_report.SEQUENCE_COLUMNS == publish.SEQUENCE_HEADLINE
    # the report prints the records' lines, the verdicts' own two among them
    defs = verdicts.definitions()
    for name, text in records.definitions().items():
        assert defs[name] == text
    assert list(defs)[-1] == "ci" and "ref_rmse" in defs
    assert list(defs).index("ref_rmse") < min(
        list(defs).index(n) for n in records.definitions(("temporal", "video")))
    for name in records.judged():
        assert f"{name}_surface" in defs["surface"]


def test_a_new_record_reaches_every_reader(monkeypatch):
    """Adding a metric is one record: directions, --rank-by, the headline and the printed
    definitions read it (each of them is looked up here after the record is added)."""
    zz = Metric("zz", "ZZ = a throwaway metric for this test", higher_is_better=True,
                range=(0.0, 1.0), rankable=True, error_map=_err_sq, has_surface_variant=True,
                headline=frozenset({"steady"}))
    with pytest.raises(DbenchInputError, match="valid: "):
        args.check_rank_by("zz")
    monkeypatch.setattr(records, "METRICS", records._build((*records._RECORDS, zz)))
    assert verdicts.higher_is_better("zz") and verdicts.higher_is_better("zz_surface")
    assert metrics.higher_is_better("zz")
    assert "zz" in args.RANKABLE and "zz_surface" in args.rankable()
    args.check_rank_by("zz")
    args.check_rank_by("zz_surface")
    assert "zz" in verdicts.headline_columns("steady")
    assert "zz" not in verdicts.headline_columns("sequence")
    text = run_report.metric_definitions_md()
    assert "- **zz**: ZZ = a throwaway metric for this test" in text
    assert "zz_surface" in verdicts.definitions()["surface"]
    assert "zz" in records.cell_columns() and "zz_surface" in records.cell_columns()


def _inputs(shape, seed):
    rng = np.random.default_rng(seed)
    r = rng.random(shape) ** 2 * 3
    o = np.abs(r + rng.normal(0, 0.2, shape))
    return o, r, rng.random(shape) * 0.01


def _pixel_mean(x):
    return x.reshape(x.shape[0], x.shape[1], -1).mean(axis=-1)


@pytest.mark.parametrize("shape, ev", [((40, 36, 3), 0.0), ((6, 7, 3), 0.5),
                                       ((24, 20, 5, 3), -1.0), ((17, 30, 1), 0.0)])
def test_record_maps_equal_the_judges_to_the_last_bit(shape, ev):
    o, r, v = _inputs(shape, seed=sum(shape))
    maps, weights = J.pixel_maps(o, r, list(J.JUDGED), v, ev)
    a = metrics.tonemap(o.sum(axis=2) if o.ndim == 4 else o, ev)
    b = metrics.tonemap(r.sum(axis=2) if r.ndim == 4 else r, ev)
    for name in J.JUDGED:
        m = METRICS[name]
        got, weight = m.per_pixel_map(*((a, b) if m.domain == "ldr" else (o, r)))
        assert got.dtype == np.float64 and got.shape == shape[:2]
        assert np.array_equal(got, maps[name]), name
        if weight is not None:
            assert np.array_equal(weight, weights[name]), name
    # the arithmetic the judge used before the maps moved to the records, written out
    d2 = (o - r) ** 2
    eps = 1e-2
    written = {"rmse": _pixel_mean(d2), "relmse": _pixel_mean(d2 / (r * r + eps)),
               "smape": _pixel_mean(np.abs(o - r) / (np.abs(o) + np.abs(r) + eps)),
               "psnr": _pixel_mean((a - b) ** 2)}
    for name, ref in written.items():
        assert np.array_equal(maps[name], ref), name
    assert np.array_equal(maps["rmse:refvar"], _pixel_mean(v))
    assert np.array_equal(maps["relmse:refvar"], _pixel_mean(v / (r * r + eps)))


def test_compute_reads_the_records_and_values_stay_in_range():
    o, r, _ = _inputs((20, 22, 3), seed=5)
    values = metrics.compute_all(o, r)
    for name, value in values.items():
        lo, hi = METRICS[name].range
        assert lo <= value <= hi, name
        assert value == metrics.compute(name, o, r)
    for name in ("mse", "rmse", "relmse", "smape", "rmae", "psnr", "ssim", "flip", "hdrflip"):
        assert getattr(metrics, name)(o, r) == values[name], name
    for name in metrics.PER_BIN_METRICS:
        m = METRICS[name]
        mean = float(np.mean(m.errors(o, r)))
        assert values[name] == (mean if m.from_mean is None else float(m.from_mean(mean)))
    # with a reference variance, so that the unbiased forms have a value to bound
    judged = J.judge(o, r, reference_var=np.full(r.shape, 1e-3)).values
    for name in J.metric_names():
        lo, hi = METRICS[name].range
        assert lo <= judged[name] <= hi, name
