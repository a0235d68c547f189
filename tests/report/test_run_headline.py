"""What ``dbench run`` and ``dbench sweep`` print first (README.md, "Usage"): the
report's ranking with intervals, surface column, time and device, the verdict words with the
size of each loss, skipped methods grouped by reason, and with ``--quiet`` nothing else: no
progress bars, no library warnings (those go to run.log and are counted in report.md)."""
from __future__ import annotations

import itertools
import re

import numpy as np
import pandas as pd
import pytest

from dbench.report import headline, run_report as report, terminal, verdicts
from dbench.cli import main

TINY = ["--scene", "cornell", "--res", "16", "--spp", "4", "--ref-spp", "64", "--repeats", "1"]
BAR = re.compile(r"\d+%\||[█▏▎▍▌▋▊▉]|it/s|pass/s|spp/s|\r")


def _table_rows(printed: str) -> list[tuple[str, str]]:
    """(place, method) of the terminal's ranked table, in order."""
    lines = printed.splitlines()
    start = next(i for i, ln in enumerate(lines) if re.match(r"#\s+method\s", ln))
    rows = []
    for ln in lines[start + 1:]:
        if not ln.strip():
            break
        place, method = ln.split()[:2]
        rows.append((place, method))
    return rows


def _report_order(md: str) -> list[str]:
    lines = md.splitlines()
    head = next(i for i, ln in enumerate(lines) if ln.startswith("| method |"))
    return [ln.split("|")[1].strip() for ln in itertools.takewhile(
        lambda ln: ln.startswith("|"), lines[head + 2:])]


def _flat(text: str) -> str:
    return " ".join(text.split())


@pytest.mark.mitsuba
def test_run_prints_the_reports_ranking_intervals_and_verdicts(renderer, tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["run", "--method", "noisy,jbf,statistical,oidn,svgf", *TINY,
                 "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    md = (out / "report.md").read_text(encoding="utf-8")
    rows = _table_rows(printed)
    # the terminal's rows are report.md's rows, in the same order (ranked by relMSE)
    assert [m for _, m in rows] == _report_order(md)
    assert [m for _, m in rows] != sorted(m for _, m in rows)  # not alphabetical here
    header = next(ln for ln in printed.splitlines() if re.match(r"#\s+method\s", ln))
    assert header.split()[2:] == ["relmse", "relmse_surface", "rmse", "rmse_surface", "time"]
    table = printed.splitlines()
    for place, method in rows:
        line = next(ln for ln in table if ln.split()[:2] == [place, method])
        assert line.count("±") == 4 and line.rstrip().endswith("cpu")
        assert len(line) <= terminal.WIDTH
    # the ranking sentence and every verdict are report.md's own words
    ranking = next(ln for ln in md.splitlines() if ln.startswith("Ranking by relmse "))
    assert ranking.rstrip(".").replace("Ranking", "ranking", 1) in _flat(printed)
    words = [ln.split("|")[-2].strip() for ln in md.splitlines()
             if ln.startswith("| ") and "worse than noisy" in ln]
    assert words and all(_flat(w) in _flat(printed) for w in words)
    assert "reference: 64 spp, estimated RMSE 0.0" in printed
    assert all(len(ln) <= terminal.WIDTH for ln in printed.splitlines() if "report:" not in ln)
    # skipped methods: one line, grouped by the kind of reason
    assert [ln for ln in printed.splitlines() if "skip" in ln] == [
        "skipped: svgf (sequence only)"]
    assert "## Library warnings" in md


@pytest.mark.mitsuba
def test_demo_run_quiet_prints_no_bars_warnings_or_skips(renderer, tmp_path, capsys,
                                                         monkeypatch):
    """scripts/bench.sh's first command at a tiny size, on an empty cache (the reference is
    rendered, so its progress bar would show), with a method whose calls warn as libraries
    do."""
    import warnings

    from dbench import registry

    cls = registry.method_class("noisy")
    plain = cls.denoise

    def warns(self, data):
        np.nanmean(np.full(3, np.nan))  # NumPy: "Mean of empty slice"
        warnings.warn("a library's note", UserWarning)
        return plain(self, data)

    monkeypatch.setattr(cls, "denoise", warns)
    out = tmp_path / "run"
    assert main(["run", "--method", "all", *TINY, "--seeds", "2", "--quiet",
                 "--cache", str(tmp_path / "cache"), "--out", str(out)]) == 0
    cap = capsys.readouterr()
    both = cap.out + cap.err
    assert not BAR.search(both), both
    assert "Warning" not in both and "warning" not in both and "skip" not in both
    assert "ranking by relmse" in cap.out
    log = (out / "run.log").read_text(encoding="utf-8")
    n = int(log.split()[0])
    assert n >= 2 and "RuntimeWarning" in log and "a library's note" in log
    md = (out / "report.md").read_text(encoding="utf-8")
    assert f"{n} library warnings, see run.log." in md
    # without --quiet: one skipped line for the scene, the warnings counted, never shown
    assert main(["run", "--method", "all", *TINY, "--cache", str(tmp_path / "cache"),
                 "--out", str(out)]) == 0
    cap = capsys.readouterr()
    skips = [ln for ln in cap.out.splitlines() if "skip" in ln]
    assert len(skips) == 1 and skips[0].startswith("skipped: ")
    assert "(sequence only)" in _flat(cap.out) and "(transient only)" in _flat(cap.out)
    assert "library warnings, see run.log" in cap.out and "RuntimeWarning" not in cap.out + cap.err


@pytest.mark.mitsuba
def test_demo_sweep_quiet_prints_no_bars_and_a_summary_per_scene(renderer, tmp_path, capsys):
    """The demo's sweep at a tiny size on an empty cache: its references are rendered before
    the cells, with no bar under --quiet; the summary ranks each scene."""
    assert main(["sweep", "--methods", "noisy,jbf,svgf,gauss3d", "--scenes", "cornell,caustic",
                 "--spp", "4", "--res", "12", "--ref-spp", "16", "--repeats", "1",
                 "--cache", str(tmp_path / "cache"), "--out", str(tmp_path / "sweep"),
                 "--quiet"]) == 0
    cap = capsys.readouterr()
    assert not BAR.search(cap.out + cap.err), cap.out + cap.err
    assert "skip" not in cap.out and "Warning" not in cap.out + cap.err
    for scene in ("caustic", "cornell"):
        assert re.search(rf"^{scene} at 4 spp \(reference 16 spp.*\): ranking by relmse",
                         cap.out, re.M)
    assert main(["sweep", "--methods", "noisy,jbf,svgf,gauss3d", "--scenes", "cornell,caustic",
                 "--spp", "4", "--res", "12", "--ref-spp", "16", "--repeats", "1",
                 "--cache", str(tmp_path / "cache"), "--out", str(tmp_path / "sweep")]) == 0
    skips = [ln for ln in capsys.readouterr().out.splitlines() if "skip" in ln]
    assert skips == ["skipped: gauss3d (transient only); svgf (sequence only)"]


def _cells(**method) -> pd.DataFrame:
    noisy = {"method": "noisy", "rmse": 0.1, "rmse_surface": 0.05, "relmse": 0.02,
             "relmse_surface": 0.02, "ssim": 0.8, "flip": 0.2, "time_s": 1e-5}
    row = {**noisy, "method": "jbf", "time_s": 0.03, **method}
    d = pd.DataFrame([noisy, row])
    for c in ("rmse", "rmse_surface", "relmse", "relmse_surface", "ssim", "flip"):
        d[c + "_ci"] = d[c] * 1e-3  # intervals far apart: no tie words
    return d


def test_flags_name_the_loss_and_where_it_comes_from():
    # 12× noisy's whole-image rmse, 0.9× its rmse over surface pixels: the lights lose it
    d = _cells(rmse=1.2, rmse_surface=0.045)
    words = headline.verdict_words(d, verdicts.HEADLINE, "relmse")
    assert words["jbf"] == ("worse than noisy on rmse 12×, from directly seen lights: "
                            "rmse_surface 0.9×")
    assert words["noisy"] == "noisy input"
    # the same words in report.md's table and on the terminal
    assert headline.scene_table(d, verdicts.HEADLINE, "relmse").set_index(
        "method").loc["jbf", "verdict"] == words["jbf"]
    assert _flat(" ".join(terminal.verdict_lines(d, verdicts.HEADLINE, "relmse"))) == \
        f"jbf: {words['jbf']}"
    # a loss on surfaces that the whole image hides; SSIM's loss as a difference (it is signed),
    # PSNR's in dB
    d = _cells(rmse=0.08, rmse_surface=0.1, ssim=0.6, psnr=20.0)
    d.loc[d.method == "noisy", "psnr"] = 22.6
    d["psnr_ci"] = 0.01
    words = headline.worse_than_noisy(d, ["rmse_surface", "ssim", "psnr"])
    assert words["jbf"] == ("worse than noisy on rmse_surface 2× (whole image 0.8×); "
                            "ssim −0.2; psnr −2.6 dB")
    assert headline.worse_than_noisy(_cells(), verdicts.HEADLINE) == {}
    # losses the intervals cannot tell from none are named once, at the end
    d = _cells(rmse=0.12, flip=0.3)
    d["rmse_ci"] = 0.05
    assert headline.worse_than_noisy(d, verdicts.HEADLINE)["jbf"] == (
        "worse than noisy on rmse 1.2×, from directly seen lights: rmse_surface 1×; flip 1.5× "
        "(tied: intervals overlap on rmse)")


def test_skips_group_by_the_kind_of_reason():
    skipped = {"bmfr": "bmfr works on ['sequence'], not on steady data",
               "gauss3d": "gauss3d works on ['transient'], not on steady data",
               "svgf": "svgf works on ['sequence'], not on steady data",
               "jbf": "jbf needs ['albedo', 'normal'], which the scene cannot provide",
               "nca": "needs weights"}
    assert _flat(terminal.skipped_line(skipped)) == (
        "skipped: bmfr, svgf (sequence only); gauss3d (transient only); jbf (needs albedo, "
        "normal); nca (needs weights)")
    assert terminal.skip_kind("x works on ['sequence', 'steady'], not on transient data") == \
        "sequence or steady only"
    assert terminal.skipped_line({}) == ""
    # a method with a counterpart for the data at hand names it (dbench/denoiser.py)
    from dbench.registry import get
    on_video = {m: get(m).applies_to("transient")[1] for m in ("jbf", "oidn", "svgf", "bmfr")}
    assert on_video["jbf"].endswith("; on transient data: jbf-bins")
    assert _flat(terminal.skipped_line(on_video)) == (
        "skipped: jbf, oidn (steady only; on transient data: jbf-bins, oidn-bins); svgf, bmfr "
        "(sequence only)")
    long = {f"method-{k}": "works on ['sequence'], not on steady data" for k in range(30)}
    assert all(len(ln) <= terminal.WIDTH for ln in terminal.skipped_line(long).splitlines())


def test_comparison_captions_never_overlap_at_the_smallest_size():
    """--res 1 (dbench/resolution.py: a side >= 1) and thin strips: every title and caption's
    rendered extent is clear of every other and of every image."""
    rng = np.random.default_rng(0)
    for h, w in ((1, 1), (1, 64), (64, 1), (16, 16)):
        ref = rng.random((h, w, 3)).astype(np.float32)
        images = [(name, (ref * rng.uniform(0.5, 2, ref.shape)).astype(np.float32))
                  for name in ("noisy", "jbf", "statistical", "oidn[quality=fast]")]
        fig = report.comparison_figure(images, ref, title=f"cornell, 4 spp, {w}×{h} px")
        fig.set_dpi(report.GRID_DPI)
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        texts = [t for ax in fig.axes for t in (ax.title, ax.yaxis.label) if t.get_text()]
        texts += [fig._suptitle] if fig._suptitle is not None else []
        boxes = [(t.get_text(), t.get_window_extent(renderer)) for t in texts]
        pictures = [im.get_window_extent(renderer) for ax in fig.axes for im in ax.images]
        assert len(boxes) >= 3 * len(images)
        for (a, box_a), (b, box_b) in itertools.combinations(boxes, 2):
            assert not box_a.overlaps(box_b), (h, w, a, b)
        for a, box in boxes:
            assert not any(box.overlaps(p) for p in pictures), (h, w, a)
        import matplotlib.pyplot as plt
        plt.close(fig)


def test_run_summary_fits_and_says_an_unknown_reference():
    rows = [{"method": "noisy", "relmse": 1.23456e-7, "relmse_ci": 1.2e-8, "time_s": 1e-5},
            {"method": "statistical[radius=12,alpha=0.001,base=jbf]", "relmse": 2.3456e-7,
             "relmse_ci": float("nan"), "time_s": 12.5}]
    d = pd.DataFrame(rows)
    for c in ("rmse", "rmse_surface", "relmse_surface"):
        d[c], d[c + "_ci"] = d["relmse"] * 1.0123456e9, d["relmse"] * 1.1e8
    settings = {"scene": "renders", "spp": 16, "res": "1280x720", "seeds": "0",
                "device": "cuda (NVIDIA H200)", "ref_spp": None,
                "reference RMSE (estimated)": "unknown (no variance layer)"}
    lines = terminal.run_summary(d, settings, "relmse", verdicts.HEADLINE,
                                 {"noisy": "cpu", d.method[1]: "cuda"})
    assert all(len(ln) <= terminal.WIDTH for ln in lines), "\n".join(lines)
    text = "\n".join(lines)
    assert "reference: unknown spp, estimated RMSE unknown (no variance layer)" in text
    assert "± n/a" in text and "12.5 s cuda" in text and "10 µs cpu" in text
    header = next(ln for ln in lines if ln.startswith("#"))
    assert header.split()[2] == "relmse" and "rmse_surface" in header
    assert "not shown" not in text
    # a column left out to fit is named, never silently missing
    wide = d.copy()
    for c in ("rmse", "rmse_surface", "relmse_surface"):
        wide[c], wide[c + "_ci"] = wide["relmse"], 1.2e-8
    lines = terminal.run_summary(wide, settings, "relmse", verdicts.HEADLINE)
    header = next(ln for ln in lines if ln.startswith("#"))
    assert " rmse " not in f" {header} " and "rmse_surface" in header
    assert all(len(ln) <= terminal.WIDTH for ln in lines), "\n".join(lines)
    assert "(not shown, to fit 100 columns: rmse; report.md has them)" in "\n".join(lines)
    # an estimate with its source is rounded as report.md rounds it
    settings["reference RMSE (estimated)"] = "0.006342895671915049 (variance image v.var.exr)"
    text = "\n".join(terminal.run_summary(d, settings, "relmse", verdicts.HEADLINE))
    assert "estimated RMSE 0.00634 (variance image v.var.exr)" in text


def test_a_small_flagged_loss_never_reads_as_one():
    """A loss the verdict flags is written with the digits that show it: 1.0025× is not 1×."""
    from dbench.report.headline import loss_size

    assert loss_size(1.0025, 1.0, "flip") == "1.002×"
    assert loss_size(0.04017, 0.04, "rmse") == "1.004×"
    assert loss_size(12.3, 1.0, "rmse") == "12.3×" and loss_size(1.04, 1.0, "rmse") == "1.04×"


def test_an_ssim_loss_is_a_difference_not_a_ratio():
    """SSIM is signed: a ratio of -0.2 to -0.05 read as a 4× loss, 0.5 to 0.9 as 0.56×."""
    from dbench.report.headline import loss_size

    assert loss_size(-0.2, -0.05, "ssim") == "−0.15"
    assert loss_size(0.5, 0.9, "ssim_surface") == "−0.4"
    assert loss_size(30.0, 32.5, "psnr") == "−2.5 dB"
