"""E5.3's detectors compared on the same walks (issue 29): each detector's "in time" against the thesis's torso band,
McNemar's exact test over the walks that changed terrain, Holm-adjusted over the detectors compared; and the false
alarms of the feet's slope against the band's over every walk.

    python docs/experiments/e5_detectors_test.py [OUT [NAME [SEEDS]]]  # OUT: chapter5.sh's runs (runs/chapter5)

Reads OUT/NAME_sN for the seeds N in SEEDS (default 0,1,2; 3,4,5,6,7 for chapter5_heldout.sh's) (NAME: detectors,
the default, or detectors_wins for the walks of best_by wins) (``scenarios/e5_detectors.yaml``, every detector
watched on every walk, none switching) with the same rows and the same "in time" as the ``detection`` section of
``sfl report``."""

import sys
from pathlib import Path

import yaml

from sfl_brain.report.conditions import Trials, mcnemar_exact
from sfl_brain.report.stats import holm
from sfl_brain.report.terrain import detection_rows, fired_early, fired_in_time

BAND = "torso"  # the thesis's detector (L1759)


def main() -> None:
    out = Path(sys.argv[1] if len(sys.argv) > 1 else "runs/chapter5")
    name = sys.argv[2] if len(sys.argv) > 2 else "detectors"  # detectors_wins: the walks of best_by wins
    seeds = [int(x) for x in sys.argv[3].split(",")] if len(sys.argv) > 3 else [0, 1, 2]
    runs = [out / f"{name}_s{seed}" for seed in seeds]
    print(f"{name}, seeds {', '.join(map(str, seeds))}")
    scenario = yaml.safe_load((runs[0] / "scenario.yaml").read_text())
    analysis = next(a for a in scenario["protocol"]["analyses"] if a["kind"] == "detection")
    limit, level = float(analysis.get("latency", 0.5)), float(analysis.get("pitch_below", -5.0))
    rows = detection_rows(Trials(scenario, runs), runs, analysis)
    first = min(r["detector"] for r in rows)  # each walk's rows come together, its detectors in sorted order
    walks: list[dict] = []
    for r in rows:
        if r["detector"] == first:
            walks.append({})
        walks[-1][r["detector"]] = r

    def in_time(r: dict) -> bool:
        return fired_in_time(r, limit)

    changed = [w for w in walks if w[BAND]["reached"] is not None]
    band = sum(in_time(w[BAND]) for w in changed)
    print(f"{len(walks)} walks, {len(changed)} changed terrain; in time: within {limit:g} s, before pitch < {level:g}")
    tests = []
    for detector in sorted(set(walks[0]) - {BAND}):
        pairs = [(in_time(w[BAND]), in_time(w[detector])) for w in changed]
        p, only_band, only_it = mcnemar_exact(pairs)
        tests.append((p, detector, only_band, only_it, sum(b for _, b in pairs)))
    tests.sort()
    adjusted = holm({detector: p for p, detector, *_ in tests})
    for p, detector, only_band, only_it, n in tests:
        print(
            f"  {detector}: in time {n}/{len(changed)} against the band's {band}/{len(changed)}; McNemar p = {p:.2g} "
            f"(only the band {only_band} / only {detector} {only_it}); Holm-adjusted {adjusted[detector]:.2g}"
        )
    pairs = [(fired_early(w[BAND]), fired_early(w["foot_slope"])) for w in walks]
    p, only_band, only_feet = mcnemar_exact(pairs)
    print(
        f"  false alarms over {len(walks)} walks: the band {sum(a for a, _ in pairs)}, foot_slope "
        f"{sum(b for _, b in pairs)}; McNemar p = {p:.2g} (only the band {only_band} / only the feet {only_feet})"
    )


if __name__ == "__main__":
    main()
