#!/usr/bin/env bash
# Chapter 5's switching walks (E5.3, issue 29) on seeds that no setting was chosen on. The 4-s start, the slope
# estimate's 30 /s and best_by wins were each chosen from walks of seeds 0-2's learnt neurons (chapter5.md, "Issue 29");
# this runs the same learn runs (adaptive vigilance, 100 trials, every terrain) and the same switching walks
# (scenarios/e5_switch.yaml, both neuron choices) on SEEDS (default 3 4) into the same OUT as chapter5.sh, and writes
# their pages into docs/results/chapter5/heldout/ (the thesis's neuron) and heldout/wins/ (the most-winning one).
# About 25 minutes on 2 cores.
#   bash docs/experiments/chapter5_heldout.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
OUT=${OUT:-runs/chapter5}
RESULTS=${RESULTS:-docs/results/chapter5/heldout}
JOBS=${JOBS:-2}
TRIALS=${TRIALS:-100}
SEEDS=${SEEDS:-3 4}
mkdir -p "$OUT" "$RESULTS"

source docs/experiments/_once.sh  # once DIR COMMAND...: a completed run folder is kept
export -f once

UP="--set conditions.body.slope_deg=10"
DOWN="--set conditions.body.slope_deg=-10"
ADAPTIVE="--set modules.vigilance.params.mode=adaptive --set modules.vigilance.params.value=0"
SHORT="--set protocol.trials=$TRIALS"
{
  for seed in $SEEDS; do
    S="--set seed=$seed --set lockstep.pin_cpus=never"
    echo "once $OUT/flat_adaptive_s$seed sfl run scenarios/e5_learn.yaml $S $SHORT $ADAPTIVE"
    echo "once $OUT/uphill_adaptive_s$seed sfl run scenarios/e5_learn.yaml $S $SHORT $UP $ADAPTIVE"
    echo "once $OUT/downhill_adaptive_s$seed sfl run scenarios/e5_learn.yaml $S $SHORT $DOWN $ADAPTIVE"
  done
} | xargs -P "$JOBS" -I{} bash -c "{}"

switch=()
switch_wins=()
learn=()
for seed in $SEEDS; do
  learn+=("$OUT/flat_adaptive_s$seed" "$OUT/uphill_adaptive_s$seed" "$OUT/downhill_adaptive_s$seed")
  FLAT="--set protocol.best_of.flat=$OUT/flat_adaptive_s$seed"
  UPHILL="--set protocol.best_of.uphill=$OUT/uphill_adaptive_s$seed"
  DOWNHILL="--set protocol.best_of.downhill=$OUT/downhill_adaptive_s$seed"
  once "$OUT/switch_s$seed" sfl run scenarios/e5_switch.yaml --set seed=$seed --set protocol.best_by=reward \
    $FLAT $UPHILL $DOWNHILL
  once "$OUT/switch_wins_s$seed" sfl run scenarios/e5_switch.yaml --set seed=$seed --set protocol.best_by=wins \
    $FLAT $UPHILL $DOWNHILL
  switch+=("$OUT/switch_s$seed")
  switch_wins+=("$OUT/switch_wins_s$seed")
done
sfl report "${switch[@]}" --out "$RESULTS"
sfl report "${switch_wins[@]}" --out "$RESULTS/wins"
sfl report "${learn[@]}" --out "$RESULTS/learn"
