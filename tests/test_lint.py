"""The linter's rules (pyproject.toml, [tool.ruff.lint]) hold over the package, the tests and
the scripts: no undefined or unused names, no imports out of place (CONTRIBUTING.md)."""
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_ruff_finds_nothing():
    # the ruff of the environment the tests run in (installed with the test extras)
    exe = Path(sys.executable).with_name("ruff")
    exe = str(exe) if exe.is_file() else shutil.which("ruff")
    assert exe, "ruff is not installed: pip install -e '.[test]'"
    out = subprocess.run([exe, "check", "--no-cache", "dbench", "tests", "scripts"], cwd=ROOT,
                         capture_output=True, text=True)
    assert out.returncode == 0, out.stdout + out.stderr
