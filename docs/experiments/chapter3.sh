#!/usr/bin/env bash
# Chapter 3 of the thesis, end to end: every run of E3.1-E3.5 into runs/, then one report in
# docs/results/chapter3/. About 25 minutes on 2 cores (two chains run side by side).
#   bash docs/experiments/chapter3.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
OUT=${OUT:-runs/chapter3}
mkdir -p "$OUT"

source docs/experiments/_once.sh  # once DIR COMMAND...: a completed run folder is kept

# a study whose high-vigilance runs stall (exit code 3) is still a study: those runs are marked in
# its report and left out of every mean; any other failure stops the script
study() {
  local code=0
  sfl study "$@" --quiet || code=$?
  if [ "$code" -ne 0 ] && [ "$code" -ne 3 ]; then exit "$code"; fi
}

# E3.2 at s_vig 0.05 alone first, so that its wall time is measured on an idle machine
once "$OUT/e3_2_s005" sfl run scenarios/e3_2_flat_s005.yaml

chain_a() {
  once "$OUT/e3_2_s0" sfl run scenarios/e3_2_flat_s0.yaml
  once "$OUT/e3_2_s-0.1" sfl run scenarios/e3_2_flat_s01.yaml
  once "$OUT/e3_2_s-0.2" sfl run scenarios/e3_2_flat_s02.yaml
  rm -rf "$OUT/e3_3a"
  study scenarios/e3_2_flat_s0.yaml --vary modules.vigilance.params.value=0.3,0.2,0.1,0.05,0,-0.1 --seeds 11,12,13 \
    --set protocol.trials=150 --set protocol.max_decisions=20000 --set record.body_every=0 \
    --out "$OUT/e3_3a"
}
chain_b() {
  once "$OUT/e3_1" sfl run scenarios/e3_1_viability.yaml
  once "$OUT/e3_4_s0" sfl run scenarios/e3_4_slopes.yaml
  once "$OUT/e3_4_s-0.2" sfl run scenarios/e3_4_slopes.yaml --set modules.vigilance.params.value=-0.2
  once "$OUT/e3_5_exploit" sfl run scenarios/e3_5_terrain.yaml --set "protocol.maps=../$OUT/e3_4_s0/acc.npz"
  once "$OUT/e3_5_fixed" sfl run scenarios/e3_5_fixed.yaml
  rm -rf "$OUT/e3_3b"
  study scenarios/e3_2_flat_s0.yaml --vary modules.vigilance.params.value=-0.2,-0.3,-0.4,-0.5 --seeds 11,12,13 \
    --set protocol.trials=150 --set protocol.max_decisions=20000 --set record.body_every=0 \
    --out "$OUT/e3_3b"
}
chain_a & A=$!
chain_b & B=$!
wait $A
wait $B
sfl report "$OUT"/e3_1 "$OUT"/e3_2_* "$OUT"/e3_4_* "$OUT"/e3_5_* "$OUT"/e3_3a/value* "$OUT"/e3_3b/value* \
  --out docs/results/chapter3
