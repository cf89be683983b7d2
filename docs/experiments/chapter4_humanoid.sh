#!/usr/bin/env bash
# Chapter 4 of the thesis on the humanoid (E4.5-E4.7, docs/results/chapter4/humanoid.md), end to end: the default
# gait over 10 seeds, E4.5 (six 250-s walks, the Poincare map of torso pitch, the cobweb figure), E4.6 (11 deg
# uphill around the thesis's alpha_MLR, theta_MLR) and E4.7 (a 34 N push at 7 timings, weaker pushes, both as balls). Each
# script's tables go to $OUT/<name>.md (default runs/chapter4/humanoid); the cobweb figure to docs/results/chapter4/.
# About 6 minutes on 2 quiet cores (5 min 25 s at 19:55 UTC, 2026-11-23).
#   bash docs/experiments/chapter4_humanoid.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
OUT=${OUT:-runs/chapter4/humanoid}
mkdir -p "$OUT"
run() {
  local name=$1; shift
  echo "$name: python $*"
  python "$@" > "$OUT/$name.md"
}
run gait docs/experiments/humanoid_gait.py --walk 10
run e4_5_poincare docs/experiments/e4_5_poincare.py --seeds 0 1 2 --noise 0.02 0.08 \
  --figure docs/results/chapter4/e4_5_cobweb.png
run e4_6_uphill docs/experiments/e4_6_uphill.py
run e4_7_push_34n docs/experiments/e4_7_push.py
run e4_7_push_weaker docs/experiments/e4_7_push.py --forces 5 10 20 --times 9 9.33
run e4_7_ball docs/experiments/e4_7_push.py --ball 1
run e4_7_ball_weaker docs/experiments/e4_7_push.py --ball 1 --forces 5 10 20 --times 9 9.33
echo "tables in $OUT/"
