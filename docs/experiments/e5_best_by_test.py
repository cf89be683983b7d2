"""Issue 29: which learnt neuron the walks take (``protocol.best_by``), compared on the same starts.

    python docs/experiments/e5_best_by_test.py [OUT [SEEDS]]  # OUT: chapter5.sh's run folder (default runs/chapter5)

For each walk that issue 29's goals count (E5.3's flat -> uphill and downhill -> flat with switching, the uphill
neuron from a flat run-up with its ankles adapted), the walks of ``best_by reward`` (the thesis's neuron nearest the
highest-reward trial, L1584: OUT/NAME_sN) against those of ``best_by wins`` (the success neuron that won the most
successes: OUT/NAME_wins_sN), seeds SEEDS (default 0,1,2; 3,4,5,6,7 for chapter5_heldout.sh's): the same seed's
conditions run draws the same start for the same repeat, so each start pairs. McNemar's exact test per walk,
Holm-adjusted over the walks compared."""

import sys
from pathlib import Path


from sfl_brain.report.conditions import mcnemar_exact, outcomes_by_start
from sfl_brain.report.stats import holm

#: (run name, condition): the walks the goals count
WALKS = [("switch", "up_switching"), ("switch", "down_switching"), ("uphill_runup", "adapted")]


def outcomes(folder: Path, condition: str) -> dict[int, bool]:
    """Repeat (the start) -> success, for the condition's trials of one run."""
    return {repeat: ok for (c, repeat), ok in outcomes_by_start(folder).items() if c == condition}


def main() -> None:
    out = Path(sys.argv[1] if len(sys.argv) > 1 else "runs/chapter5")
    seeds = [int(x) for x in sys.argv[2].split(",")] if len(sys.argv) > 2 else [0, 1, 2]
    found = {}
    for name, condition in WALKS:
        pairs = []
        for seed in seeds:
            reward = outcomes(out / f"{name}_s{seed}", condition)
            wins = outcomes(out / f"{name}_wins_s{seed}", condition)
            if reward.keys() != wins.keys():
                sys.exit(f"{name} seed {seed}: the two runs hold different repeats of {condition}")
            pairs += [(reward[k], wins[k]) for k in sorted(reward)]
        p, only_reward, only_wins = mcnemar_exact(pairs)
        found[f"{name}/{condition}"] = (p, pairs, only_reward, only_wins)
    adjusted = holm({k: v[0] for k, v in found.items()})
    print(f"walk: best_by reward (L1584) vs best_by wins, seeds {', '.join(map(str, seeds))}; McNemar exact, Holm over "
          "the walks compared")
    for key, (p, pairs, only_reward, only_wins) in found.items():
        n = len(pairs)
        print(
            f"  {key}: reward {sum(a for a, _ in pairs)}/{n}, wins {sum(b for _, b in pairs)}/{n}; McNemar p = {p:.2g} "
            f"(only reward {only_reward} / only wins {only_wins}); Holm-adjusted {adjusted[key]:.2g}"
        )


if __name__ == "__main__":
    main()
