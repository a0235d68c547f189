#!/usr/bin/env bash
# Runs the test suite (sets up first if needed), without the tests marked slow (the stress
# matrix's device-form cases through Triton's interpreter, the 128-px temporal quality check,
# the transient media windows, ...). Extra arguments go to pytest, e.g.
# scripts/test.sh -m slow (only the slow ones) or scripts/test.sh -m "" (everything).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
export DBENCH_CACHE=${DBENCH_CACHE:-$PWD/.dbench-cache/tests}
# Bytecode is written (to __pycache__, which git ignores) even where PYTHONDONTWRITEBYTECODE is
# set: without it each worker rewrites the asserts of every test module at collection (about 7 s
# of a worker's 11 on 2 cores) and every process a test starts compiles dbench's modules again.
unset PYTHONDONTWRITEBYTECODE
exec .venv/bin/python -m pytest -n 2 -q -m "not slow" "$@"
