# Sourced by the chapter-5 scripts (chapter5.sh, chapter5_heldout.sh, chapter5_floor.sh): what they share. Needs OUT,
# JOBS and TRIALS set.
source docs/experiments/_once.sh  # once DIR COMMAND...: a completed run folder is kept
export -f once

UP="--set conditions.body.slope_deg=10"
DOWN="--set conditions.body.slope_deg=-10"
ADAPTIVE="--set modules.vigilance.params.mode=adaptive --set modules.vigilance.params.value=0"
SHORT="--set protocol.trials=$TRIALS"

# learn_runs SEED...: E5.2/E5.3's adaptive learn runs on every terrain, JOBS at a time (learning is one trial after
# another, so a run keeps one core busy)
learn_runs() {
  local seed S
  for seed in "$@"; do
    S="--set seed=$seed --set lockstep.pin_cpus=never"  # runs side by side: the OS spreads them over the cores
    echo "once $OUT/flat_adaptive_s$seed sfl run scenarios/e5_learn.yaml $S $SHORT $ADAPTIVE"
    echo "once $OUT/uphill_adaptive_s$seed sfl run scenarios/e5_learn.yaml $S $SHORT $UP $ADAPTIVE"
    echo "once $OUT/downhill_adaptive_s$seed sfl run scenarios/e5_learn.yaml $S $SHORT $DOWN $ADAPTIVE"
  done | xargs -P "$JOBS" -I{} bash -c "{}"
}

# neurons SEED: sets FLAT, UPHILL and DOWNHILL, the flags that point a walk at SEED's learn runs (protocol.best_of)
neurons() {
  FLAT="--set protocol.best_of.flat=$OUT/flat_adaptive_s$1"
  UPHILL="--set protocol.best_of.uphill=$OUT/uphill_adaptive_s$1"
  DOWNHILL="--set protocol.best_of.downhill=$OUT/downhill_adaptive_s$1"
}

# walk_runs SEED: the walks with SEED's learnt neurons (two body workers: both cores), taken two ways
# (protocol.best_by): the thesis's, the success neuron nearest the highest-reward trial (L1584: runs NAME_sN), and
# the success neuron that won the most successful trials (runs NAME_wins_sN)
walk_runs() {
  local seed=$1 by tag choice
  neurons "$seed"
  for by in reward wins; do
    tag=$([ $by = wins ] && echo _wins || true)
    choice="--set protocol.best_by=$by"
    once "$OUT/switch${tag}_s$seed" sfl run scenarios/e5_switch.yaml --set seed=$seed $choice $FLAT $UPHILL $DOWNHILL
    once "$OUT/switch_flat${tag}_s$seed" sfl run scenarios/e5_switch_flat.yaml --set seed=$seed $choice $FLAT $UPHILL
    once "$OUT/uphill_runup${tag}_s$seed" sfl run scenarios/e5_uphill_runup.yaml --set seed=$seed $choice $UPHILL
    once "$OUT/detectors${tag}_s$seed" sfl run scenarios/e5_detectors.yaml --set seed=$seed $choice $FLAT $UPHILL \
      $DOWNHILL
  done
}

# report_walks RESULTS SEED...: the pages of walk_runs' runs of SEEDs, the thesis's neuron's into RESULTS and the
# most-winning neuron's into RESULTS/wins
report_walks() {
  local results=$1 name seed
  shift
  for name in switch switch_flat uphill_runup detectors; do
    local runs=() wins=()
    for seed in "$@"; do
      runs+=("$OUT/${name}_s$seed")
      wins+=("$OUT/${name}_wins_s$seed")
    done
    sfl report "${runs[@]}" --out "$results"
    sfl report "${wins[@]}" --out "$results/wins"
  done
}
