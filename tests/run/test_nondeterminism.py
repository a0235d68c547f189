"""A method whose calls on one input give different outputs (an unseeded random number, a
``reset()`` that leaves state behind, an output that alternates between two values) is flagged:
the harness compares every call's output with the first's (the warm-up), exactly, NaN in the
same places equal, and the cell, the run's output and the reports say its numbers are not
reproducible and which calls differed (dbench/run/harness.py; README.md, "Usage")."""
from __future__ import annotations

import json

import numpy as np
import pytest

from dbench import cli
from dbench.data import Frame
from dbench.registry import Denoiser
from dbench.report.formats import markdown_text
from dbench.report.headline import verdict_words
from dbench.report.tables import cells_frame
from dbench.run import harness
from dbench.run.inputs import merge_difference, output_difference
from dbench.run.sequence_run import run_sequence
from dbench.synthetic import synthetic_sequence
from exr_files import write_rgb  # tests/exr_files.py
from sweep_cells import ok_cell  # tests/sweep_cells.py

H, W = 12, 16


class _Steady(Denoiser):
    kinds = {"steady"}
    needs = {"color"}
    defaults = {}


class Unseeded(_Steady):
    """A plug-in's unseeded noise: every call draws other numbers."""
    name = "unseeded"

    def denoise(self, data):
        return (data.color + np.random.normal(0, 1e-3, data.color.shape)).astype(np.float32)


class Counter(_Steady):
    """State that ``reset()`` (the base class's, which does nothing) leaves behind."""
    name = "counter"

    def __init__(self):
        super().__init__()
        self.calls = 0

    def denoise(self, data):
        self.calls += 1
        return data.color * np.float32(1 + 1e-4 * self.calls)


class Steady(_Steady):
    """Deterministic, with a NaN always in the same pixel."""
    name = "steady"

    def denoise(self, data):
        out = data.color * np.float32(0.5)
        out[0, 0, 0] = np.nan
        return out


class Alternates(_Steady):
    """Two outputs in turn (A, B, A, …): over an odd number of calls the first and the last
    are equal, and only the calls between them show it."""
    name = "alternates"

    def __init__(self):
        super().__init__()
        self.calls = 0

    def denoise(self, data):
        self.calls += 1
        return data.color * np.float32(1.0 if self.calls % 2 else 0.5)


class Reuses(_Steady):
    """Writes every call into one buffer that it returns: the first output must be copied."""
    name = "reuses"

    def __init__(self):
        super().__init__()
        self.buffer, self.calls = None, 0

    def denoise(self, data):
        self.calls += 1
        if self.buffer is None:
            self.buffer = np.empty_like(data.color)
        self.buffer[:] = data.color + np.float32(self.calls)
        return self.buffer


def _frame(seed: int = 0) -> Frame:
    rng = np.random.default_rng(seed)
    color = rng.uniform(0.1, 1.0, (H, W, 3)).astype(np.float32)
    return Frame(color=color, reference=np.full((H, W, 3), 0.5, np.float32),
                 meta={"seed": seed})


def _cell(method, frames=None, **kw):
    res = harness.run_cell(method, frames or _frame(), metric_names=["rmse"], **kw)
    return res, harness.cell_record(res, harness._as_list(frames or _frame()), {"color"})


def test_an_unseeded_random_output_is_flagged_in_the_cell_record():
    res, record = _cell(Unseeded(), repeats=2)
    nd = record["nondeterministic"]
    assert nd["seeds"] == [0] and nd["calls"] == "calls 2-3 of 3 differed from the first"
    assert 0 < nd["max_abs_diff"] < 0.02 and 0 < nd["max_rel_diff"] < 0.02
    json.dumps(record)  # a sweep writes it as it is


def test_a_reset_that_leaves_a_call_counter_behind_is_flagged():
    m = Counter()
    res, record = _cell(m, repeats=3)
    assert m.calls == 4  # no call was added for the comparison
    nd = record["nondeterministic"]
    # the last call's output (× 1.0004) against the first's (× 1.0001)
    peak = float(_frame().color.max())
    assert nd["max_abs_diff"] == pytest.approx(3e-4 * peak, rel=1e-2)
    assert nd["max_rel_diff"] == pytest.approx(3e-4 / 1.0004, rel=1e-2)


def test_an_output_alternating_between_two_values_is_flagged_and_its_calls_named():
    m = Alternates()
    res, record = _cell(m, repeats=2, warmup=1)  # A, B, A: the first and the last are equal
    assert m.calls == 3  # no call was added for the comparison
    nd = record["nondeterministic"]
    assert nd["seeds"] == [0] and nd["calls"] == "call 2 of 3 differed from the first"
    peak = float(_frame().color.max())
    assert nd["max_abs_diff"] == pytest.approx(0.5 * peak)
    assert nd["max_rel_diff"] == pytest.approx(1.0)  # over the largest value of call 2's
    # the scored output is still the last call's (A)
    np.testing.assert_array_equal(res.output, _frame().color)
    m = Alternates()
    res, record = _cell(m, repeats=4, warmup=1)  # A, B, A, B, A
    assert record["nondeterministic"]["calls"] == "calls 2, 4 of 5 differed from the first"


def test_the_calls_named_are_those_of_every_seed():
    frames = [_frame(0), _frame(1)]
    frames[1].reference = frames[0].reference
    m = Alternates()  # seed 0: A, B, A; seed 1: B, A, B (its count goes on)
    res, record = _cell(m, frames, repeats=2, warmup=1)
    nd = record["nondeterministic"]
    assert nd["seeds"] == [0, 1] and nd["calls"] == "call 2 of 3 differed from the first"
    np.testing.assert_array_equal(res.output, frames[0].color)


class DeviceAlternates(Alternates):
    """The same on the device route, writing every call into one output tensor."""
    name = "device-alternates"

    def denoise_device(self, data):
        self.calls += 1
        if getattr(self, "buffer", None) is None:
            self.buffer = data.color.clone()
        self.buffer.copy_(data.color * (1.0 if self.calls % 2 else 0.5))
        return self.buffer


def test_the_device_route_compares_every_call_too(monkeypatch):
    pytest.importorskip("torch")
    # CPU tensors stand in for a GPU (as in tests/run/test_device.py): the same code
    monkeypatch.setattr(harness, "placement",
                        lambda m, d: (d != "cpu" and m.runs_on_device(), "cpu"))
    res = harness.run_cell(DeviceAlternates(), _frame(), metric_names=["rmse"], repeats=2,
                           device="cuda")
    assert res.transfer_s and res.nondeterministic["calls"] == ("call 2 of 3 differed from "
                                                                "the first")
    np.testing.assert_array_equal(res.output, _frame().color)


def test_timed_calls_keeps_one_copy_and_compares_every_later_call_untimed():
    outputs = iter([np.zeros(3), np.ones(3), np.zeros(3), np.full(3, 2.0)])
    kept = []

    def keep(out):
        kept.append(out.copy())
        return kept[-1]

    last, times, apart = harness.timed_calls(lambda: next(outputs), repeats=3, warmup=1,
                                             keep=keep)
    assert len(kept) == 1 and len(times) == 3  # one copy, of the first call; three timed
    np.testing.assert_array_equal(last, np.full(3, 2.0))  # the last call's, as before
    assert apart == {"max_abs_diff": 2.0, "max_rel_diff": 1.0, "calls": [2, 4], "of": 4}
    same = harness.timed_calls(lambda: np.ones(3), repeats=2, warmup=1, keep=np.copy)
    assert same[2] == {}
    assert harness.timed_calls(lambda: np.ones(3), repeats=2, warmup=1)[2] == {}  # no keep


def test_a_deterministic_method_with_nan_in_the_same_place_is_not_flagged():
    res, record = _cell(Steady(), repeats=2)
    assert res.nondeterministic == {} and "nondeterministic" not in record
    assert res.n_nonfinite == 1


def test_an_output_buffer_reused_by_every_call_is_compared_as_it_was_returned():
    res, record = _cell(Reuses(), repeats=1)
    assert record["nondeterministic"]["max_abs_diff"] == pytest.approx(1.0)


def test_every_seed_whose_calls_differ_is_named():
    frames = [_frame(0), _frame(1)]
    for f in frames[1:]:
        f.reference = frames[0].reference
    res, record = _cell(Counter(), frames, repeats=1)
    assert record["nondeterministic"]["seeds"] == [0, 1]


def test_a_single_call_has_nothing_to_compare():
    res, record = _cell(Unseeded(), repeats=1, warmup=0)
    assert "nondeterministic" not in record


def test_output_difference():
    a = np.array([[1.0, np.nan, 3.0]], np.float32)
    assert output_difference(a, a.copy()) is None
    b = a.copy()
    b[0, 2] = 3.5
    assert output_difference(a, b) == {"max_abs_diff": 0.5, "max_rel_diff": 0.5 / 3.5}
    c = a.copy()
    c[0, 1] = 2.0  # a number where the other call gave NaN
    assert output_difference(a, c)["max_abs_diff"] == float("inf")
    assert output_difference(a, a[:, :2])["max_abs_diff"] == float("inf")
    z = np.zeros((2, 2), np.float32)
    assert output_difference(z, z + 1)["max_rel_diff"] == 1.0


def test_merge_difference_keeps_the_largest_of_each_and_the_other_keys():
    found = {"seeds": [0], "max_abs_diff": 0.5, "max_rel_diff": 0.01}
    merged = merge_difference(found, {"max_abs_diff": 0.25, "max_rel_diff": 0.02})
    assert merged == {"seeds": [0], "max_abs_diff": 0.5, "max_rel_diff": 0.02}
    assert found["max_rel_diff"] == 0.01  # left unchanged
    assert merge_difference({}, {"max_abs_diff": float("inf"), "max_rel_diff": 1.0}) == {
        "max_abs_diff": float("inf"), "max_rel_diff": 1.0}
    assert merge_difference(found, None) == found


class Recurrent(Denoiser):
    """A temporal method whose ``reset()`` forgets to clear its history."""
    name = "recurrent"
    kinds = {"sequence"}
    needs = {"color"}
    defaults = {}

    def __init__(self, clears: bool = False):
        super().__init__()
        self.clears, self.history = clears, None

    def reset(self):
        if self.clears:
            self.history = None

    def denoise(self, data):
        color = np.asarray(data.color, np.float32)
        self.history = color if self.history is None else 0.5 * (self.history + color)
        return self.history.copy()


def test_a_sequence_whose_warm_up_frames_come_out_otherwise_after_reset_is_flagged():
    seq = synthetic_sequence(8, 8, frames=4)
    run = run_sequence(Recurrent(), seq, warmup=8)
    assert run.nondeterministic["frames"] == [0, 1]
    assert run_sequence(Recurrent(clears=True), seq, warmup=8).nondeterministic is None
    res = harness.run_sequence_cell(Recurrent(), seq, metric_names=["rmse"], warmup=8,
                                    cvvdp=False)
    assert res.nondeterministic["calls"] == ("frames 0, 1 in the untimed warm-up and in the "
                                             "run")


def test_a_sequence_longer_than_its_warm_up_has_frames_0_1_run_again_after_the_run():
    """No untimed pass runs before a sequence longer than the warm-up (its first frames are
    the warm-up): frames 0-1 are run again after it, untimed, and compared."""
    seq = synthetic_sequence(8, 8, frames=12)
    calls = []

    class Counting(Recurrent):
        def denoise(self, data):
            calls.append(1)
            return super().denoise(data)

    run = run_sequence(Counting(), seq, warmup=8)
    assert len(calls) == 14 and run.nondeterministic["frames"] == [0, 1]
    assert run.nondeterministic["pass"] == "an untimed second pass after the run"
    assert len(run.per_frame) == 12  # the second pass is neither timed nor scored
    assert run_sequence(Recurrent(clears=True), seq, warmup=8).nondeterministic is None
    res = harness.run_sequence_cell(Recurrent(), seq, metric_names=["rmse"], warmup=8,
                                    cvvdp=False)
    assert res.nondeterministic["calls"] == ("frames 0, 1 in an untimed second pass after the "
                                             "run and in the run")


def test_the_verdict_says_not_reproducible():
    flagged = ok_cell("box", 4, "unseeded")
    flagged["nondeterministic"] = {"seeds": [0], "max_abs_diff": 3.1e-5, "max_rel_diff": 2e-5}
    d = cells_frame([ok_cell("box", 4, "noisy", err=0.05), flagged, ok_cell("box", 4, "jbf")])
    words = verdict_words(d, ["rmse"], "rmse")
    assert words["unseeded"] == ("not reproducible: calls on one input gave different outputs "
                                 "(largest difference 3.1e-05, 0.002 % of the output's largest "
                                 "value)")
    assert words["jbf"] == ""


PLUGIN = '''
import numpy as np
from dbench.registry import Denoiser, register

@register("test-unseeded")
class Unseeded(Denoiser):
    kinds = {"steady"}
    needs = {"color"}
    def denoise(self, data):
        return (data.color + np.random.normal(0, 1e-3, data.color.shape)).astype(np.float32)
'''


def _folder(path):
    path.mkdir()
    rng = np.random.default_rng(0)
    truth = rng.uniform(0.2, 1.0, (H, W, 3))
    noise = rng.normal(size=truth.shape) * 0.1 * truth
    write_rgb(path / "v_0004.hdr.exr", (truth + noise).astype(np.float32))
    write_rgb(path / "v_ref.hdr.exr", truth.astype(np.float32))
    return path


def test_run_and_sweep_say_it(tmp_path, capsys, isolated):
    plugin = tmp_path / "unseeded.py"
    plugin.write_text(PLUGIN)
    folder = _folder(tmp_path / "renders")
    common = ["--spp", "4", "--repeats", "1", "--quiet", "--cache", str(tmp_path / "cache")]
    rc = cli.main(["--plugin", str(plugin), "run", "--method", "noisy,test-unseeded",
                   "--scene", str(folder), *common, "--out", str(tmp_path / "run")])
    printed = capsys.readouterr()
    assert rc == 0, printed.err
    said = [line for line in printed.err.splitlines() if "same input" in line]
    assert len(said) == 1 and said[0].startswith(
        "warning: test-unseeded: two calls on the same input gave different outputs (largest "
        "difference ") and said[0].endswith(
        "; seed 0, call 2 of 2 differed from the first): its numbers are those of the last "
        "call and are "
        "not reproducible"), printed.err
    assert "noisy:" not in printed.err
    report = (tmp_path / "run" / "report.md").read_text(encoding="utf-8")
    notes = report.split("## Notes")[1]
    assert markdown_text(said[0].removeprefix("warning: ")) in notes
    assert report.count("not reproducible: calls on one input") == 1  # its verdict
    assert "not reproducible: calls on one input" in " ".join(printed.out.split())  # verdicts

    rc = cli.main(["--plugin", str(plugin), "sweep", "--methods", "noisy,test-unseeded",
                   "--scenes", str(folder), *common, "--out", str(tmp_path / "sweep")])
    printed = capsys.readouterr()
    assert rc == 0, printed.err
    cells = {p.stem: json.loads(p.read_text())
             for p in (tmp_path / "sweep").rglob("cells/**/*.json")}
    assert len(cells["test-unseeded"]["nondeterministic"]["seeds"]) == 1
    assert "nondeterministic" not in cells["noisy"]
    # the headline's verdict, then one warning at every spp where the cells differed
    out = " ".join(printed.out.split())  # as wrapped at 100 columns
    assert "not reproducible: calls on one input" in out
    assert "warning: v at 4 spp: test-unseeded: two calls on the same input " \
        "gave different outputs" in out


def test_the_sweep_readme_and_page_list_the_cells_at_every_spp():
    from dbench.report.html import nondeterministic_html
    from dbench.report.publish import nondeterministic_md

    cells = [ok_cell("box", spp, "unseeded") for spp in (16, 4)] + [ok_cell("box", 4, "jbf")]
    cells[0]["nondeterministic"] = {"seeds": [0], "max_abs_diff": 1e-3, "max_rel_diff": 1e-3,
                                    "calls": "first and last of 6 calls"}
    cells[1]["nondeterministic"] = {"seeds": [0, 1], "max_abs_diff": 2e-3,
                                    "max_rel_diff": 4e-3, "calls": "first and last of 6 calls"}
    md = nondeterministic_md(cells, "## Not reproducible")
    assert md[0] == "## Not reproducible" and len([x for x in md if x.startswith("- ")]) == 1
    assert ("- box at 4, 16 spp: unseeded: two calls on the same input gave different outputs "
            "(largest difference 0.002, 0.4 % of the output's largest value; seeds 0, 1, first "
            "and last of 6 calls): its numbers are those of the last call and are not "
            "reproducible") in md
    assert nondeterministic_md(cells[2:], "## Not reproducible") == []
    page = "".join(nondeterministic_html(cells))
    assert "box at 4, 16 spp: unseeded: two calls" in page
