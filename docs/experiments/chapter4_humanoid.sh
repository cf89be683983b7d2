#!/usr/bin/env bash
# Chapter 4 of the thesis on the humanoid, end to end, every experiment a scenario that `sfl run` runs over processes
# (records, a Rerun recording, a status) into runs/chapter4/humanoid/, and `sfl report` writing its page and figures
# into docs/results/chapter4/:
#   the default gait over 10 starts (scenarios/humanoid_gait.yaml)
#   E4.5  250-s walks and the Poincare return map of the torso pitch (e4_5_poincare.yaml)
#   E4.6  walking onto an 11-degree slope around the thesis's alpha_MLR, theta_MLR, sigma_s swept (e4_6_uphill.yaml)
#   E4.7  pushes of 0-34 N at 10 phases of the gait with and without L1437's switch (e4_7_push.yaml), and a real ball
#         (e4_7_ball.yaml)
# A run folder that already holds a completed run is kept (re-running resumes). About 45 minutes on 2 cores.
#   bash docs/experiments/chapter4_humanoid.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
OUT=${OUT:-runs/chapter4/humanoid}
RESULTS=${RESULTS:-docs/results/chapter4}
mkdir -p "$OUT" "$RESULTS"

source docs/experiments/_once.sh  # once DIR COMMAND...: a completed run folder is kept

for name in humanoid_gait e4_5_poincare e4_6_uphill e4_7_push e4_7_ball; do
  once "$OUT/$name" sfl run "scenarios/$name.yaml"
  sfl report "$OUT/$name" --out "$RESULTS"
done
