"""One writer per sweep folder: a second sweep into a locked ``--out`` is refused with one line
naming the holder (exit 2); the lock of a sweep that is gone is taken over with a note."""
import json
import os
import socket
import subprocess
import sys

import pytest

from dbench import cli
from dbench.run import sweep_lock
from dbench.errors import DbenchInputError


def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def _sweep_args(out, *extra):
    return ["sweep", "--methods", "noisy", "--scenes", "cornell", "--spp", "2", "--res", "8",
            "--ref-spp", "16", "--repeats", "1", "--out", str(out), "--quiet", *extra]


def test_a_second_sweep_into_a_locked_folder_is_refused_naming_the_holder(tmp_path):
    out = tmp_path / "S"
    out.mkdir()
    fd = sweep_lock.acquire(out)
    try:
        env = {**os.environ, "DBENCH_CACHE": str(tmp_path / "cache")}
        proc = subprocess.run([sys.executable, "-m", "dbench.cli", *_sweep_args(out)], env=env,
                              capture_output=True, text=True, timeout=300)
    finally:
        sweep_lock.release(out, fd)
    err = proc.stderr.strip()
    assert proc.returncode == 2, proc.stderr
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert f"pid {os.getpid()} on {socket.gethostname()}, since " in err and str(out) in err
    assert sorted(p.name for p in out.iterdir()) == []  # nothing written, lock file gone
    assert not (tmp_path / "cache").exists()


def test_the_lock_is_per_open_file_and_released(tmp_path):
    fd = sweep_lock.acquire(tmp_path)
    record = json.loads((tmp_path / sweep_lock.LOCK_NAME).read_text())
    assert record["pid"] == os.getpid() and record["host"] == socket.gethostname()
    with pytest.raises(DbenchInputError, match="another sweep is writing there"):
        sweep_lock.acquire(tmp_path)  # another open of the file, even in this process
    sweep_lock.release(tmp_path, fd)
    assert not (tmp_path / sweep_lock.LOCK_NAME).exists()
    sweep_lock.release(tmp_path, sweep_lock.acquire(tmp_path))


def test_a_refused_sweep_removes_the_folder_it_created(tmp_path):
    out = tmp_path / "new"
    with pytest.raises(DbenchInputError):
        with sweep_lock.hold(out):
            raise DbenchInputError("refused")
    assert not out.exists()


def test_without_flock_a_live_holder_refuses_and_a_dead_one_is_taken_over(tmp_path,
                                                                          monkeypatch, capsys):
    monkeypatch.setattr(sweep_lock, "fcntl", None)
    lock = tmp_path / sweep_lock.LOCK_NAME
    live = {"pid": os.getppid(), "host": socket.gethostname(), "since": "then"}
    lock.write_text(json.dumps(live))
    with pytest.raises(DbenchInputError, match=f"pid {os.getppid()} on"):
        sweep_lock.acquire(tmp_path)
    lock.write_text(json.dumps({**live, "pid": _dead_pid()}))
    sweep_lock.release(tmp_path, sweep_lock.acquire(tmp_path))
    assert "no longer running" in capsys.readouterr().err


@pytest.mark.mitsuba
def test_a_stale_lock_of_a_dead_sweep_is_taken_over(renderer, tmp_path, capsys, monkeypatch):
    out = tmp_path / "S"
    out.mkdir()
    dead = _dead_pid()
    (out / sweep_lock.LOCK_NAME).write_text(json.dumps(
        {"pid": dead, "host": socket.gethostname(), "since": "2020-01-01 00:00:00 +0000"}))
    monkeypatch.setenv("DBENCH_CACHE", str(tmp_path / "cache"))
    rc = cli.main(_sweep_args(out))
    err = capsys.readouterr().err
    assert rc == 0, err
    assert f"taking over the lock of a sweep that is no longer running (pid {dead} on" in err
    assert not (out / sweep_lock.LOCK_NAME).exists()
    assert len(list(out.glob("cells/*/*/*.json"))) == 1
