#!/usr/bin/env bash
# Chapter 5's switching walks (E5.3, issue 29) on seeds that no setting was chosen on. The 4-s start, the slope
# estimate's 30 /s and best_by wins were each chosen from walks of seeds 0-2's learnt neurons (chapter5.md, "Issue 29");
# this runs the same learn runs (adaptive vigilance, 100 trials, every terrain) and the same walks as chapter5.sh's
# second stage (the switching walks, the switch on flat ground, the uphill run-up, the detectors; both neuron
# choices) on SEEDS (default 3 4 5 6 7) into the same OUT as chapter5.sh, and writes their pages into
# docs/results/chapter5/heldout/ (the thesis's neuron), heldout/wins/ (the most-winning one) and heldout/learn/.
# About 20 minutes on 2 cores.
#   bash docs/experiments/chapter5_heldout.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
OUT=${OUT:-runs/chapter5}
RESULTS=${RESULTS:-docs/results/chapter5/heldout}
JOBS=${JOBS:-2}
TRIALS=${TRIALS:-100}
SEEDS=${SEEDS:-3 4 5 6 7}
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

learn=()
for seed in $SEEDS; do
  learn+=("$OUT/flat_adaptive_s$seed" "$OUT/uphill_adaptive_s$seed" "$OUT/downhill_adaptive_s$seed")
  FLAT="--set protocol.best_of.flat=$OUT/flat_adaptive_s$seed"
  UPHILL="--set protocol.best_of.uphill=$OUT/uphill_adaptive_s$seed"
  DOWNHILL="--set protocol.best_of.downhill=$OUT/downhill_adaptive_s$seed"
  for by in reward wins; do
    TAG=$([ $by = wins ] && echo _wins || true)
    BY="--set protocol.best_by=$by"
    once "$OUT/switch${TAG}_s$seed" sfl run scenarios/e5_switch.yaml --set seed=$seed $BY $FLAT $UPHILL $DOWNHILL
    once "$OUT/switch_flat${TAG}_s$seed" sfl run scenarios/e5_switch_flat.yaml --set seed=$seed $BY $FLAT $UPHILL
    once "$OUT/uphill_runup${TAG}_s$seed" sfl run scenarios/e5_uphill_runup.yaml --set seed=$seed $BY $UPHILL
    once "$OUT/detectors${TAG}_s$seed" sfl run scenarios/e5_detectors.yaml --set seed=$seed $BY $FLAT $UPHILL $DOWNHILL
  done
done
for name in switch switch_flat uphill_runup detectors; do
  runs=()
  wins=()
  for seed in $SEEDS; do
    runs+=("$OUT/${name}_s$seed")
    wins+=("$OUT/${name}_wins_s$seed")
  done
  sfl report "${runs[@]}" --out "$RESULTS"
  sfl report "${wins[@]}" --out "$RESULTS/wins"
done
sfl report "${learn[@]}" --out "$RESULTS/learn"
# the same tests as chapter5.sh's, over these seeds: the detectors against the torso band, and the two neuron choices
SEEDLIST=$(echo $SEEDS | tr ' ' ',')
python docs/experiments/e5_detectors_test.py "$OUT" detectors "$SEEDLIST"
python docs/experiments/e5_detectors_test.py "$OUT" detectors_wins "$SEEDLIST"
python docs/experiments/e5_best_by_test.py "$OUT" "$SEEDLIST"
