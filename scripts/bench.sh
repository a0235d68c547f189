#!/usr/bin/env bash
# The main job: set everything up, then run a small benchmark that ends in a report.
#   results/demo/run-cornell/report.md   one `dbench run` (table printed, comparison.png, EXRs;
#                                        index.html: the interactive viewer)
#   results/demo/run-flicker/report.md   the temporal methods on an animated sequence
#   results/demo/run-cornell-transient/  the transient methods on a time-resolved video
#   results/demo/README.md               a small sweep + stress test, published by `dbench report`
#                                        (results/demo/index.html: the same, sortable)
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
export PATH="$PWD/.venv/bin:$PATH"
RES=${DBENCH_DEMO_RES:-96}
SCENES=${DBENCH_DEMO_SCENES:-cornell,caustic,textured}
dbench run --method all --scene cornell --spp 16 --res "$RES" --seeds 2 --out results/demo/run-cornell --quiet
dbench run --method all --scene flicker --spp 1 --res 64 --frames 24 --ref-spp 256 \
  --out results/demo/run-flicker --quiet
dbench run --method all --scene cornell-transient --spp 64 --res 32 --bins 100 --ref-spp 1024 \
  --repeats 3 --out results/demo/run-cornell-transient --quiet
dbench sweep --methods all --scenes "$SCENES" --spp 4,16,64 --res "$RES" --repeats 3 --seeds 2 --rerun \
  --out results/demo/sweep --quiet
dbench stress --out results/demo/stress.md --quiet > /dev/null || true
dbench report --results results/demo --sweep results/demo/sweep
.venv/bin/python scripts/viewer_screenshot.py results/demo/run-cornell results/demo/viewer.png \
  || echo "viewer screenshot skipped (no chromium)"
dbench bench render --res 256 --spp 64
dbench bench metrics
echo
echo "demo report: results/demo/README.md (runs: results/demo/run-*/report.md)"
