#!/usr/bin/env bash
# Chapter 4 of the thesis on the 8-link planar walker, end to end, every body experiment a scenario that `sfl run` runs
# over processes (records, a Rerun recording, a status) into runs/chapter4/, and `sfl report` writing its page and
# figures into docs/results/chapter4/:
#   E4.1  one joint's patterns, domination, deletion (the network alone: docs/experiments/e4_1_patterns.py)
#   E4.2  the grid of patterns that walk (scenarios/e4_2_grid.yaml), learning (sigma_s, sigma_f) over seeds 0, 1, 2
#         (scenarios/e4_2_learn.yaml)
#   E4.3  a push for a step, without phase resetting, with the state reset and with the pulse (e4_3_pushes.yaml)
#   E4.4  a 45 N push, without and with pattern switching, voltage motors and position servos (e4_4_pushes*.yaml)
# A run folder that already holds a completed run is kept (re-running resumes). About 25 minutes on 2 cores.
#   bash docs/experiments/chapter4.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
OUT=${OUT:-runs/chapter4}
RESULTS=${RESULTS:-docs/results/chapter4}
mkdir -p "$OUT" "$RESULTS"

source docs/experiments/_once.sh  # once DIR COMMAND...: a completed run folder is kept

python docs/experiments/e4_1_patterns.py --out "$RESULTS" > /dev/null
once "$OUT/e4_2_grid" sfl run scenarios/e4_2_grid.yaml
sfl report "$OUT/e4_2_grid" --out "$RESULTS"
for seed in 0 1 2; do
  once "$OUT/e4_2_s$seed" sfl run scenarios/e4_2_learn.yaml --set seed=$seed
done
sfl report "$OUT"/e4_2_s0 "$OUT"/e4_2_s1 "$OUT"/e4_2_s2 --out "$RESULTS"
for name in e4_3_pushes e4_4_pushes e4_4_pushes_servo; do
  once "$OUT/$name" sfl run "scenarios/$name.yaml"
  sfl report "$OUT/$name" --out "$RESULTS"
done
