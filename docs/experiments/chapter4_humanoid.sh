#!/usr/bin/env bash
# Chapter 4 of the thesis on the humanoid, end to end, every experiment a scenario that `sfl run` runs over processes
# (records, a Rerun recording, a status) into runs/chapter4/humanoid/, and `sfl report` writing its page and figures
# into docs/results/chapter4/:
#   the default gait over 10 starts (scenarios/humanoid_gait.yaml)
#   E4.5  250-s walks and the Poincare return map of the torso pitch (e4_5_poincare.yaml)
#   E4.6  walking from the flat onto an 11-degree slope around the thesis's alpha_MLR, theta_MLR, with and without the
#         ankle adaptation (e4_6_uphill.yaml), seeds 0, 1, 2
#   E4.7  pushes of 0-34 N at 10 phases of the gait with and without L1437's switch (e4_7_push.yaml), a real ball
#         (e4_7_ball.yaml), and the same pushes on a body of the thesis's 4.3 kg (e4_7_push_43kg.yaml, seeds 0-2)
#   the flat gait's margin: the largest push it survives at 10 phases of its cycle (humanoid_margin.yaml, seeds 0-3)
# A run folder that already holds a completed run is kept (re-running resumes). About 90 minutes on 2 cores.
#   bash docs/experiments/chapter4_humanoid.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
OUT=${OUT:-runs/chapter4/humanoid}
RESULTS=${RESULTS:-docs/results/chapter4}
mkdir -p "$OUT" "$RESULTS"

source docs/experiments/_once.sh  # once DIR COMMAND...: a completed run folder is kept

for name in humanoid_gait e4_5_poincare e4_7_push e4_7_ball; do
  once "$OUT/$name" sfl run "scenarios/$name.yaml"
  sfl report "$OUT/$name" --out "$RESULTS"
done
for name in e4_7_push_43kg e4_6_uphill humanoid_margin; do  # seeds 0, 1, 2 (the margin also 3), pooled on one page
  seeds=(0 1 2)
  if [ "$name" = humanoid_margin ]; then seeds=(0 1 2 3); fi  # issue 29: >= 10 phases x >= 4 seeds
  runs=()
  for seed in "${seeds[@]}"; do
    once "$OUT/${name}_s$seed" sfl run "scenarios/$name.yaml" --set seed=$seed
    runs+=("$OUT/${name}_s$seed")
  done
  sfl report "${runs[@]}" --out "$RESULTS"
done
# E4.6's best cell of seeds 0-2 (alpha_MLR 0.6, theta_MLR -0.15 at 3b765a1: 8/9 adapted), walked again on seeds 3-5 so
# that its count is not the luck of choosing the best of 20 cells
for seed in 3 4 5; do
  once "$OUT/e4_6_confirm_s$seed" sfl run scenarios/e4_6_uphill.yaml --set seed=$seed \
    --set 'protocol.grid.controller.alpha_mlr=[0.6]' --set 'protocol.grid.controller.theta_mlr=[-0.15]'
done
sfl report "$OUT"/e4_6_confirm_s3 "$OUT"/e4_6_confirm_s4 "$OUT"/e4_6_confirm_s5 --out "$RESULTS/e4_6_confirm"
