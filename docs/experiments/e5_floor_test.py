"""Issue 29: the feet's slope detector at a wider floor against the shipped one, start by start
(``docs/experiments/chapter5_floor.sh``).

    python docs/experiments/e5_floor_test.py [OUT [TAG [SEEDS]]]   # default runs/chapter5 floor3 0,1,2

For each neuron choice (``best_by`` reward: runs NAME_sN; wins: NAME_wins_sN) and each seed in SEEDS, the walks at the
shipped floor (OUT/switch..., OUT/detectors...) against the same scenario's walks with ``controller.foot_slope_floor``
(OUT/switch_TAG..., OUT/detectors_TAG...): the same seed and repeat draw the same start, so each walk pairs.

- **The switching walks** (``e5_switch.yaml``): per case with switching, how many walked on at each floor, McNemar's
  exact test, Holm over the four cases of a neuron choice. The cases without switching do not watch the feet, so their
  walks must be the same at both floors: that is checked, and a difference stops the script.
- **The detector walks** (``e5_detectors.yaml``, none switching, so both floors watch the same walks): per case, the
  feet's false alarms (fired before the change; on the flat walks, at all) and their detections in time (within the
  scenario's latency after a foot met the new ground and before the torso pitched below its limit), at each floor,
  with McNemar's exact test."""

import sys
from pathlib import Path

import yaml

from sfl_brain.report.conditions import Trials, mcnemar_exact, outcomes_by_start
from sfl_brain.report.stats import holm
from sfl_brain.report.terrain import detection_rows, fired_early, fired_in_time

SWITCHING = ("up_switching", "down_switching", "flatdown_switching", "upflat_switching")
WITHOUT = ("up_without", "down_without", "flatdown_without", "upflat_without")
CASES = ("flat", "up", "down", "flatdown", "upflat")


def feet(folder: Path) -> list[dict]:
    """Per logged walk of one detector run, by trial: its trial, case, whether a foot met the new ground, and whether
    the feet fired early or in time (the scenario's latency)."""
    scenario = yaml.safe_load((folder / "scenario.yaml").read_text())
    analysis = next(a for a in scenario["protocol"]["analyses"] if a["kind"] == "detection")
    rows = detection_rows(Trials(scenario, [folder]), [folder], analysis)
    walks = [r for r in rows if r["detector"] == "foot_slope"]
    if not walks:  # the feet never fired in this run: every walk's row of another detector, the feet's time unset
        walks = [dict(r, fired=None) for r in rows if r["detector"] == min(x["detector"] for x in rows)]
    limit = float(analysis.get("latency", 0.5))
    return sorted(
        (
            {"trial": w["trial"], "condition": w["condition"], "changed": w["reached"] is not None,
             "early": fired_early(w), "in_time": fired_in_time(w, limit)}
            for w in walks
        ),
        key=lambda w: w["trial"],  # runs finish their trials in any order
    )  # fmt: skip


def main() -> None:
    out = Path(sys.argv[1] if len(sys.argv) > 1 else "runs/chapter5")
    tag = sys.argv[2] if len(sys.argv) > 2 else "floor3"
    seeds = [int(x) for x in sys.argv[3].split(",")] if len(sys.argv) > 3 else [0, 1, 2]
    print(f"the feet's floor: shipped against {tag}, seeds {', '.join(map(str, seeds))}; McNemar exact, same starts")
    for by in ("", "_wins"):
        print(f"best_by {'wins' if by else 'reward'}")
        pairs: dict[str, list] = {c: [] for c in SWITCHING}
        for seed in seeds:
            shipped = outcomes_by_start(out / f"switch{by}_s{seed}")
            wider = outcomes_by_start(out / f"switch_{tag}{by}_s{seed}")
            if shipped.keys() != wider.keys():
                sys.exit(f"switch{by} seed {seed}: the two runs hold different walks")
            for key in shipped:
                if key[0] in WITHOUT and shipped[key] != wider[key]:
                    sys.exit(f"switch{by} seed {seed}: {key[0]} repeat {key[1]} differs, yet it does not switch")
                if key[0] in pairs:
                    pairs[key[0]].append((shipped[key], wider[key]))
        tests = {c: mcnemar_exact(p) for c, p in pairs.items()}
        adjusted = holm({c: t[0] for c, t in tests.items()})
        for c, (p, only_shipped, only_wider) in tests.items():
            n = len(pairs[c])
            print(
                f"  {c}: walked on {sum(a for a, _ in pairs[c])}/{n} shipped, {sum(b for _, b in pairs[c])}/{n} {tag}; "
                f"McNemar p = {p:.2g} ({only_shipped} / {only_wider}), Holm {adjusted[c]:.2g}"
            )
        walks = {c: [] for c in CASES}
        for seed in seeds:
            a, b = feet(out / f"detectors{by}_s{seed}"), feet(out / f"detectors_{tag}{by}_s{seed}")
            if [(w["trial"], w["condition"]) for w in a] != [(w["trial"], w["condition"]) for w in b]:
                sys.exit(f"detectors{by} seed {seed}: the two runs hold different walks")
            for x, y in zip(a, b, strict=True):
                walks[x["condition"]].append((x, y))
        for c, ws in walks.items():
            alarms = [(x["early"], y["early"]) for x, y in ws]
            timely = [(x["in_time"], y["in_time"]) for x, y in ws if x["changed"]]
            p_alarm, p_time = mcnemar_exact(alarms)[0], mcnemar_exact(timely)[0] if timely else float("nan")
            print(
                f"  detectors {c}: false alarms {sum(a for a, _ in alarms)}/{len(ws)} shipped, "
                f"{sum(b for _, b in alarms)}/{len(ws)} {tag} (p = {p_alarm:.2g}); in time "
                f"{sum(a for a, _ in timely)}/{len(timely)} shipped, {sum(b for _, b in timely)}/{len(timely)} {tag}"
                + (f" (p = {p_time:.2g})" if timely else "")
            )


if __name__ == "__main__":
    main()
