#!/usr/bin/env bash
# Runs the test suite (sets up first if needed). Extra arguments go to pytest,
# e.g. scripts/test.sh -m "not slow".
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
export DBENCH_CACHE=${DBENCH_CACHE:-$PWD/.dbench-cache/tests}
exec .venv/bin/python -m pytest -n 2 -q "$@"
