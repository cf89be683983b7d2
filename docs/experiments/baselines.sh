#!/usr/bin/env bash
# Safe-learning baselines side by side (issue 22; docs/results/baselines.md): every proposer of
# docs/proposers.md, five seeds each, the same trial budget, on
#   the planar reflex walker in the E3.2 setting (scenarios/baselines_planar.yaml: 200 trials; ~14 min on 2 cores)
#   the humanoid in the E5.1 setting (scenarios/baselines_humanoid.yaml: 100 trials; ~45 min on 2 cores)
# each a `sfl study` (runs over processes, JOBS at once, default 2) into runs/baselines/<body>/, its report (learning
# curves with 95 % bands, failures before K good gaits, best eta, the table) into docs/results/baselines/<body>/.
# Run again, a study keeps its finished runs and runs only the others (docs/studies.md).
#   bash docs/experiments/baselines.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
OUT=${OUT:-runs/baselines}
RESULTS=${RESULTS:-docs/results/baselines}
JOBS=${JOBS:-2}
SEEDS=${SEEDS:-0,1,2,3,4}
PROPOSERS=${PROPOSERS:-sfl,random,cma,tpe,safe_bo}
for body in planar humanoid; do
  status=0
  sfl study "scenarios/baselines_$body.yaml" --vary "protocol.proposer.kind=$PROPOSERS" --seeds "$SEEDS" \
    --jobs "$JOBS" --out "$OUT/$body" || status=$?
  # a stalled or failed run is named by the study and left out of its means; the report is written either way
  if [ "$status" -ne 0 ] && [ "$status" -ne 1 ] && [ "$status" -ne 3 ]; then exit "$status"; fi
  mkdir -p "$RESULTS/$body"
  sfl report "$OUT/$body" --out "$RESULTS/$body"
done
