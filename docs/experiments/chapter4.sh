#!/usr/bin/env bash
# Chapter 4 of the thesis on the planar walker, end to end: E4.1 (one joint's patterns), E4.2 (learning the
# pattern of the 8-link walker, seeds 0, 1, 2, each run into runs/chapter4/), the report of E4.2 in
# docs/results/chapter4/ (e4_2_learn.md and its figures), and E4.3-E4.4 (pushes) when its script is there.
# About 15 minutes on 2 shared cores: E4.1 about a minute, each E4.2 run 1.5-3 minutes (one at a time), the
# pushes about 3 minutes.
#   bash docs/experiments/chapter4.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
OUT=${OUT:-runs/chapter4}
mkdir -p "$OUT"

source docs/experiments/_once.sh  # once DIR COMMAND...: a completed run folder is kept

python docs/experiments/e4_1_patterns.py --out docs/results/chapter4 > /dev/null
for seed in 0 1 2; do
  once "$OUT/e4_2_s$seed" sfl run scenarios/e4_2_learn.yaml --set seed=$seed
done
sfl report "$OUT"/e4_2_s0 "$OUT"/e4_2_s1 "$OUT"/e4_2_s2 --out docs/results/chapter4
if [ -f docs/experiments/e4_3_e4_4_pushes.py ]; then
  python docs/experiments/e4_3_e4_4_pushes.py --out docs/results/chapter4/e4_3_e4_4_pushes.md > /dev/null
fi
