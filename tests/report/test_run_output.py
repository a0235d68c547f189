"""``dbench run`` writes its folder whole or not at all, whatever happens to stdout, the locale,
the disk or the run (README.md, "Usage"; dbench/report/run_output.py, dbench/cli/streams.py).
"""
from __future__ import annotations

import errno
import io
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from dbench import cli
from dbench.cli import streams

FILES = ("metrics.csv", "metrics_per_seed.csv", "report.md", "run.json", "index.html",
         "comparison.png", "images/reference.exr")


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    """One cache for the module: the reference renders once."""
    return tmp_path_factory.mktemp("cache")


def _argv(out: Path, cache: Path, methods: str = "noisy,jbf") -> list[str]:
    return ["run", "--method", methods, "--scene", "cornell", "--spp", "4", "--res", "16",
            "--ref-spp", "64", "--cache", str(cache), "--out", str(out)]


def _cmd(out: Path, cache: Path, methods: str = "noisy,jbf") -> list[str]:
    return [sys.executable, "-m", "dbench.cli", *_argv(out, cache, methods)]


def _leftovers(out: Path) -> list[str]:
    """Temporary folders a run left beside ``out``."""
    return sorted(p.name for p in out.parent.iterdir() if p.name.startswith(f"{out.name}."))


def _assert_complete(out: Path, methods=("noisy", "jbf")) -> None:
    for name in FILES + tuple(f"images/{m}.exr" for m in methods):
        assert (out / name).is_file(), name
    assert _leftovers(out) == []


@pytest.mark.mitsuba
def test_closed_stdout_keeps_every_file(renderer, tmp_path, cache):
    out = tmp_path / "run"
    proc = subprocess.Popen(_cmd(out, cache), stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    first = proc.stdout.readline()
    proc.stdout.close()  # the reader goes away, as `| head -1` does
    err = proc.stderr.read().decode()
    assert proc.wait() == 0, err
    assert first.startswith(b"running")
    assert "internal error" not in err and "Traceback" not in err and "Exception" not in err
    _assert_complete(out)


@pytest.mark.mitsuba
@pytest.mark.skipif(not Path("/dev/full").exists(), reason="needs /dev/full")
def test_full_stdout_keeps_every_file_and_says_so_in_one_line(renderer, tmp_path, cache):
    out = tmp_path / "run"
    with open("/dev/full", "w") as full:
        proc = subprocess.run(_cmd(out, cache) + ["--quiet"], stdout=full,
                              stderr=subprocess.PIPE, text=True)
    assert proc.returncode == 2
    assert proc.stderr == "dbench: cannot write standard output: No space left on device\n"
    _assert_complete(out)


@pytest.mark.mitsuba
def test_ascii_locale_writes_utf8_files_and_prints(renderer, tmp_path, cache):
    env = {**os.environ, "LC_ALL": "C", "LANG": "C", "PYTHONUTF8": "0"}
    env.pop("PYTHONIOENCODING", None)
    out = tmp_path / "run"
    proc = subprocess.run(_cmd(out, cache), env=env, capture_output=True)
    assert proc.returncode == 0, proc.stderr
    proc.stdout.decode("ascii")  # escaped, never a UnicodeEncodeError
    report = (out / "report.md").read_bytes().decode("utf-8")
    assert any(ord(c) > 127 for c in report)  # "±", "λ": the locale did not decide the bytes
    _assert_complete(out)
    listed = subprocess.run([sys.executable, "-m", "dbench.cli", "list"], env=env,
                            capture_output=True)
    assert listed.returncode == 0, listed.stderr
    assert b"cornell" in listed.stdout


@pytest.mark.mitsuba
def test_second_run_replaces_the_first_without_stale_files(renderer, tmp_path, cache, capsys):
    out = tmp_path / "run"
    assert cli.main(_argv(out, cache) + ["--quiet"]) == 0
    assert (out / "images" / "jbf.exr").is_file()
    assert cli.main(_argv(out, cache, "noisy") + ["--quiet"]) == 0
    assert not (out / "images" / "jbf.exr").exists()
    _assert_complete(out, ("noisy",))
    import pandas as pd
    assert set(pd.read_csv(out / "metrics.csv")["method"]) == {"noisy"}


def test_a_folder_that_is_not_a_run_is_refused_untouched(tmp_path, capsys):
    out = tmp_path / "thesis"
    out.mkdir()
    (out / "chapter1.tex").write_text("x", encoding="utf-8")
    code = cli.main(_argv(out, tmp_path / "cache") + ["--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "not a dbench run folder" in err, err
    assert sorted(p.name for p in out.iterdir()) == ["chapter1.tex"]
    assert _leftovers(out) == []


@pytest.mark.mitsuba
def test_full_disk_mid_write_is_one_line_and_leaves_nothing(renderer, tmp_path, cache, capsys,
                                                            monkeypatch):
    import pandas as pd
    out = tmp_path / "run"
    assert cli.main(_argv(out, cache, "noisy") + ["--quiet"]) == 0
    before = sorted(p.relative_to(out) for p in out.rglob("*"))
    real = pd.DataFrame.to_csv

    def disk_full_after(n):
        calls = []

        def to_csv(self, path, *a, **k):
            calls.append(path)
            if len(calls) > n:
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
            return real(self, path, *a, **k)
        return to_csv
    # metrics.csv is written, then metrics_per_seed.csv finds the disk full
    monkeypatch.setattr(pd.DataFrame, "to_csv", disk_full_after(1))
    code = cli.main(_argv(out, cache) + ["--quiet"])
    err = capsys.readouterr().err
    assert code == 2, err
    assert err == (f"dbench: cannot write {out / 'metrics_per_seed.csv'}: "
                   "No space left on device\n")
    # the earlier run is untouched, and nothing of the failed one is left anywhere
    assert sorted(p.relative_to(out) for p in out.rglob("*")) == before
    assert not (out / "images" / "jbf.exr").exists() and _leftovers(out) == []
    fresh = tmp_path / "fresh"
    monkeypatch.setattr(pd.DataFrame, "to_csv", disk_full_after(0))
    assert cli.main(_argv(fresh, cache) + ["--quiet"]) == 2
    assert capsys.readouterr().err.count("\n") == 1
    assert not fresh.exists() and _leftovers(fresh) == []


@pytest.mark.mitsuba
def test_interrupted_method_leaves_no_partial_out(renderer, tmp_path, cache, capsys,
                                                  monkeypatch):
    from dbench.methods import jbf

    def interrupted(self, data):
        raise KeyboardInterrupt
    monkeypatch.setattr(jbf.JBF, "denoise", interrupted)
    monkeypatch.setattr(jbf.JBF, "denoise_device", interrupted)
    out = tmp_path / "run"
    code = cli.main(_argv(out, cache) + ["--quiet"])
    assert code == 130
    assert capsys.readouterr().err == "dbench: interrupted\n"
    assert not out.exists() and _leftovers(out) == []


@pytest.mark.mitsuba
def test_terminated_run_leaves_no_partial_out(renderer, tmp_path):
    out = tmp_path / "run"
    # an uncached reference of many samples: the run is still rendering when the signal comes
    cmd = [sys.executable, "-m", "dbench.cli", "run", "--method", "noisy", "--scene", "cornell",
           "--spp", "4", "--res", "64", "--ref-spp", "16384", "--cache", str(tmp_path / "c"),
           "--out", str(out), "--quiet"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 60
    while time.time() < deadline and not _leftovers(out) and proc.poll() is None:
        time.sleep(0.05)
    assert _leftovers(out), "the run never started writing"
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=60) == 130, proc.stderr.read()
    assert not out.exists() and _leftovers(out) == []


def test_a_termination_whose_interrupt_was_swallowed_still_ends_the_run(tmp_path):
    # SIGTERM's interrupt can land where Python ignores exceptions (a weakref callback, a
    # __del__, a library's catch-all); the run must still end without putting its folder in place
    from dbench.report import run_output

    out = tmp_path / "run"
    before = signal.getsignal(signal.SIGTERM)
    with pytest.raises(run_output.Terminated):
        with run_output.staged(out) as stage:
            (stage / "metrics.csv").write_text("x\n")
            try:
                os.kill(os.getpid(), signal.SIGTERM)
                time.sleep(1)  # the handler runs here, its exception is swallowed below
            except KeyboardInterrupt:
                pass
    assert run_output.terminated()
    assert not out.exists() and _leftovers(out) == []
    # a bare KeyboardInterrupt that some code evaluated from a string sees pass makes CPython
    # kill the process with SIGINT at exit (exit status -2, not 130): the subclass never does
    assert issubclass(run_output.Terminated, KeyboardInterrupt)
    assert run_output.Terminated is not KeyboardInterrupt
    assert signal.getsignal(signal.SIGTERM) == before
    with run_output.staged(out) as stage:  # the next block starts clean
        (stage / run_output.MARKER).write_text("{}")
    assert not run_output.terminated() and out.is_dir()


def test_guarded_stream_drops_text_once_the_reader_is_gone():
    class Broken(io.StringIO):
        def write(self, text):
            raise BrokenPipeError(errno.EPIPE, "Broken pipe")
    guard = streams.GuardedStream(Broken())
    assert guard.write("table\n") == 6
    guard.flush()
    assert isinstance(guard.lost, BrokenPipeError) and streams.reader_gone(guard.lost)


def test_ascii_stream_escapes_what_it_cannot_encode():
    raw = io.BytesIO()
    text = io.TextIOWrapper(raw, encoding="ascii", errors="strict")
    guard = streams.GuardedStream(text)
    guard.write("λ = 0.5 ×\n")
    guard.flush()
    assert raw.getvalue() == b"\\u03bb = 0.5 \\xd7\n"


def test_openexr_disk_errors_name_the_path():
    from dbench import io as dio
    from dbench.errors import OutputError
    exc = RuntimeError('Failed to write pixel data to image file "x.tmp.exr". '
                       "No space left on device.")
    error = dio.output_error(exc, "out/images/jbf.exr")
    assert isinstance(error, OutputError)
    assert str(error) == "cannot write out/images/jbf.exr: No space left on device"
    assert dio.output_error(RuntimeError("something else"), "x") is None
    assert dio.output_error(OSError(errno.EROFS, os.strerror(errno.EROFS)), "x").reason == \
        os.strerror(errno.EROFS)
