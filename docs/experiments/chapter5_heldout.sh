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

source docs/experiments/_chapter5.sh  # once, learn_runs, walk_runs, report_walks

learn_runs $SEEDS
learn=()
for seed in $SEEDS; do
  learn+=("$OUT/flat_adaptive_s$seed" "$OUT/uphill_adaptive_s$seed" "$OUT/downhill_adaptive_s$seed")
  walk_runs $seed
done
report_walks "$RESULTS" $SEEDS
sfl report "${learn[@]}" --out "$RESULTS/learn"
# the same tests as chapter5.sh's, over these seeds: the detectors against the torso band, and the two neuron choices
SEEDLIST=$(echo $SEEDS | tr ' ' ',')
python docs/experiments/e5_detectors_test.py "$OUT" detectors "$SEEDLIST"
python docs/experiments/e5_detectors_test.py "$OUT" detectors_wins "$SEEDLIST"
python docs/experiments/e5_best_by_test.py "$OUT" "$SEEDLIST"
