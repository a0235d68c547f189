"""User mistakes get one line and exit 2 before anything renders; odd but valid requests
work."""
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from cli_args import with_options  # tests/cli_args.py

from dbench import cli


def _run(capsys, *argv):
    rc = cli.main(list(argv))
    err = capsys.readouterr().err
    return rc, err


def _base(tmp_path, *extra):
    return with_options(["run", "--method", "noisy,nca", "--scene", "cornell", "--spp", "4",
                         "--res", "8", "--ref-spp", "16", "--cache", str(tmp_path / "cache"),
                         "--out", str(tmp_path / "out"), "--quiet"], *extra)


@pytest.mark.parametrize("extra", [
    ["--res", "100000"], ["--repeats", "0"], ["--repeats", "-2"], ["--seeds", "0"],
    ["--param", "x" * 50000], ["--lam", "300"], ["--rank-by", "speed"], ["--ref-spp", "0"],
])
def test_bad_arguments_exit_2_with_one_line_and_render_nothing(tmp_path, capsys, extra):
    rc, err = _run(capsys, *_base(tmp_path, *extra))
    assert rc == 2 and err.startswith("dbench: ") and err.count("\n") == 1, err
    assert not (tmp_path / "cache").exists() and not (tmp_path / "out").exists()


def test_weights_that_are_not_an_onnx_file_are_refused(tmp_path, capsys):
    text = tmp_path / "weights.txt"
    text.write_text("not a model")
    for weights in (text, tmp_path, tmp_path / "missing.onnx"):
        rc, err = _run(capsys, *_base(tmp_path, "--param", f"nca.weights={weights}"))
        assert rc == 2 and "nca.weights" in err and "Traceback" not in err
    assert not (tmp_path / "cache").exists()


def test_unwritable_outputs_are_refused_before_rendering(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    rc, err = _run(capsys, *_base(tmp_path)[:-3], "--out", str(blocker), "--quiet")
    assert rc == 2 and "not a folder" in err
    argv = _base(tmp_path)
    argv[argv.index("--cache") + 1] = str(blocker / "cache")  # cannot be created
    rc, err = _run(capsys, *argv)
    assert rc == 2 and "--cache" in err and not (tmp_path / "out").exists()


def test_internal_errors_are_one_line_unless_debug(tmp_path, capsys, monkeypatch):
    from dbench import datasets

    def boom(*a, **k):
        raise RuntimeError("renderer exploded")
    monkeypatch.setattr(datasets, "load", boom)
    rc, err = _run(capsys, *_base(tmp_path))
    assert rc == 1 and "internal error" in err and "--debug" in err and "Traceback" not in err
    with pytest.raises(RuntimeError):
        cli.main(["--debug"] + _base(tmp_path))


def test_stress_out_may_be_a_folder(tmp_path, capsys):
    rc = cli.main(["stress", "--methods", "noisy", "--out", str(tmp_path), "--quiet"])
    assert rc == 0 and (tmp_path / "stress.md").is_file()
    rc, err = _run(capsys, "stress", "--methods", "nope", "--out", str(tmp_path))
    assert rc == 2 and "nope" in err


def test_written_files_follow_the_umask(tmp_path):
    from dbench import io
    old = os.umask(0o022)
    try:
        io.write_text(tmp_path / "a.txt", "x")
    finally:
        os.umask(old)
    assert (tmp_path / "a.txt").stat().st_mode & 0o777 == 0o644


@pytest.mark.mitsuba
def test_a_one_pixel_image_simply_works(renderer, tmp_path, capsys):
    argv = ["run", "--method", "noisy,jbf,oidn,statistical", "--scene", "cornell", "--spp",
            "4", "--res", "1", "--ref-spp", "16", "--cache", str(tmp_path / "cache"),
            "--out", str(tmp_path / "out"), "--quiet"]
    assert cli.main(argv) == 0
    assert (tmp_path / "out" / "comparison.png").is_file()


@pytest.mark.mitsuba
def test_one_frame_sequence_says_what_it_scored(renderer, tmp_path, monkeypatch):
    from dbench.report import sequence_figures

    titles = []
    for name in ("plot_errors", "strip"):  # the figures' titles, as drawn
        def drawn(*a, _f=getattr(sequence_figures, name), title="", **k):
            titles.append(title)
            return _f(*a, title=title, **k)
        monkeypatch.setattr(sequence_figures, name, drawn)
    argv = ["run", "--method", "accumulate", "--scene", "flicker", "--spp", "1", "--res", "8",
            "--frames", "1", "--ref-spp", "16", "--cache", str(tmp_path / "cache"), "--out",
            str(tmp_path / "out"), "--quiet"]
    assert cli.main(argv) == 0
    assert len(titles) == 2 and all(t.endswith(", 1 frame") for t in titles), titles
    text = (tmp_path / "out" / "report.md").read_text()
    assert "over all 1 frame (" in text and "≥ 8 of 1" not in text and "frame(s)" not in text


@pytest.mark.mitsuba
def test_killed_sweep_takes_its_workers_with_it(renderer, tmp_path):
    out = tmp_path / "S"
    env = {**os.environ, "DBENCH_CACHE": str(tmp_path / "cache")}
    cmd = [sys.executable, "-m", "dbench.cli", "sweep", "--methods", "noisy,jbf",
           "--scenes", "cornell,textured,mirrors", "--spp", "2,4,8,16", "--res", "12",
           "--ref-spp", "16", "--repeats", "1", "--workers", "2", "--out", str(out), "--quiet"]
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 120
    children: list[int] = []
    while time.time() < deadline and not children:
        time.sleep(0.2)
        children = _children(proc.pid)
    assert children, "no worker started"
    time.sleep(1.0)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    deadline = time.time() + 20
    while time.time() < deadline and any(_alive(c) for c in children):
        time.sleep(0.2)
    assert not any(_alive(c) for c in children)


def _children(pid: int) -> list[int]:
    out = []
    for status in Path("/proc").glob("[0-9]*/status"):
        try:
            text = status.read_text()
        except OSError:
            continue
        for line in text.splitlines():
            if line.startswith("PPid:") and int(line.split()[1]) == pid:
                out.append(int(status.parent.name))
    return out


def _alive(pid: int) -> bool:
    try:
        text = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False
    return "State:\tZ" not in text
