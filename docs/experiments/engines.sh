#!/usr/bin/env bash
# The humanoid on PyBullet and on MuJoCo side by side (issue 31; docs/bodies/humanoid.md, "Two engines"): chapter 4's
# humanoid gait over 10 starts (scenarios/humanoid_gait.yaml), E4.5's 250-s walks (e4_5_poincare.yaml) and a 100-trial
# E5.1 with QARL (e5_learn.yaml, protocol.trials=100, seeds 0-2), each on both engines, `sfl run` over processes into
# runs/engines/, `sfl report` pages into docs/results/engines/, and the side-by-side tables printed by
# docs/experiments/engines_table.py. One run at a time (the gait and E4.5 use both cores); about 45 minutes on 2 quiet
# cores. Needs the mujoco extra: pip install -e '.[mujoco]'.
#   bash docs/experiments/engines.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
OUT=${OUT:-runs/engines}
RESULTS=${RESULTS:-docs/results/engines}
mkdir -p "$OUT" "$RESULTS"

source docs/experiments/_once.sh  # once DIR COMMAND...: a completed run folder is kept

for engine in pybullet mujoco; do
  E="--set modules.body.params.physics=$engine"
  once "$OUT/gait_$engine" sfl run scenarios/humanoid_gait.yaml $E
  once "$OUT/e4_5_$engine" sfl run scenarios/e4_5_poincare.yaml $E
  for seed in 0 1 2; do
    once "$OUT/e5_1_${engine}_s$seed" sfl run scenarios/e5_learn.yaml $E --set protocol.trials=100 --set seed=$seed
  done
  sfl report "$OUT/gait_$engine" --out "$RESULTS/gait_$engine"
  sfl report "$OUT/e4_5_$engine" --out "$RESULTS/e4_5_$engine"
  sfl report "$OUT"/e5_1_${engine}_s* --out "$RESULTS/e5_1_$engine"
done
python docs/experiments/engines_table.py "$OUT" | tee "$RESULTS/tables.md"
