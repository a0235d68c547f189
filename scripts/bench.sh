#!/usr/bin/env bash
# The main job: set everything up, then run a small benchmark that ends in a report.
# Output: results/demo/<scene>/report.md (+ metrics.csv, comparison.png, EXRs); table on screen.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
export PATH="$PWD/.venv/bin:$PATH"
RES=${DBENCH_DEMO_RES:-128}
SPP=${DBENCH_DEMO_SPP:-16}
METHODS=${DBENCH_DEMO_METHODS:-$(dbench list --methods-only | paste -sd, -)}
for scene in ${DBENCH_DEMO_SCENES:-cornell caustic textured}; do
  dbench run --method "$METHODS" --scene "$scene" --spp "$SPP" --res "$RES" \
    --out "results/demo/$scene" --quiet
done
dbench bench render --res 256 --spp 64
