"""Chapter 5's learnt neurons walked across the terrain in one process (issue 29): where the start ramp and the ankle
adaptation's ``rate`` in ``humanoid_nao.yaml`` come from.

    python docs/calibration/humanoid_learnt.py RUNS CASE FROM [TO] [--starts 5] [--trial KEY=VALUE ...]
                                               [--set KEY=VALUE ...] [--point neuron|trial|wins]

``RUNS`` holds chapter 5's adaptive learn runs (``flat_adaptive_sN``, ``uphill_adaptive_sN``, ``downhill_adaptive_sN``,
as ``docs/experiments/chapter5.sh`` names them); for each seed N found there, the walk uses that run's best neuron
(``summary.json`` ``best.neuron_point``, as ``protocol.best_of`` does) of the terrain ``FROM`` and, given ``TO``,
switches to ``TO``'s best neuron when the feet sense the change (``e5_switch.yaml``'s switch: ``foot_slope``, band 1.5,
gradual). ``CASE`` is a ground, a finish line and a time-out (``CASES``). ``--trial`` sets the controller's trial
parameters (default ``CH5``: ``e5_learn.yaml``'s conditions; a neuron's own value too, ``--trial gain_pitch=0.8``
walks the ``FROM`` neuron with that pitch gain), ``--set`` a circuit value by key path (``ankle_adaptation.rate=10``).
Prints per seed the walks that reach the line, and each walk's end (S/f, time s, distance m). A calibration (no bus,
no records), not an experiment: the experiments are the scenarios.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
from sfl_brain.bodies.humanoid import Humanoid  # noqa: E402
from sfl_brain.body import InProcessLink  # noqa: E402
from sfl_brain.messages import TrialRequest  # noqa: E402
from sfl_brain.modules.controllers.cpg import CPGController, CPGParams  # noqa: E402
from sfl_brain.scenario.plan import most_wins  # noqa: E402

#: the chapter-5 setting of the controller (scenarios/e5_learn.yaml's conditions)
CH5 = {"ankle_adaptation": "on", "start_ramp": 4.0}
#: name -> (body trial parameters, finish line m, trial time-out s): e5_learn.yaml's ramps, e5_switch.yaml's cases
CASES = {
    "flat": ({}, 1.5, 40.0),
    "ramp10": ({"slope_deg": 10.0}, 1.5, 40.0),
    "ramp-10": ({"slope_deg": -10.0}, 1.5, 40.0),
    "onto10": ({"terrain": "1.0:0,4:10"}, 2.5, 50.0),
    "down_to_flat": ({"terrain": "1.0:-10,4:0"}, 2.5, 50.0),
    "flat_to_down": ({"terrain": "1.0:0,4:-10"}, 2.5, 50.0),
    "up_to_flat": ({"terrain": "1.0:10,4:0"}, 2.5, 50.0),
}
TERRAINS = ("flat", "uphill", "downhill")


def best(runs: Path, terrain: str, seed: int, point: str = "neuron") -> dict:
    """The learn run's best neuron (protocol.best_of's choice with best_by reward, L1584; ``point`` "trial": the
    highest-reward trial itself; "wins": best_by wins, the success neuron that won the most successes), as controller
    trial parameters."""
    folder = runs / f"{terrain}_adaptive_s{seed}"
    if point == "wins":
        found = most_wins(folder)
        if isinstance(found, str):  # why the run gives none
            sys.exit(found)
        return found
    point = json.loads((folder / "summary.json").read_text())["best"][f"{point}_point"]
    return {k: point[k] for k in ("gain_pitch", "gain_roll", "sigma_s")}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("runs", type=Path)
    parser.add_argument("case", choices=sorted(CASES))
    parser.add_argument("start", choices=TERRAINS, metavar="FROM")
    parser.add_argument("to", nargs="?", choices=TERRAINS, metavar="TO")
    parser.add_argument("--starts", type=int, default=5)
    parser.add_argument("--point", choices=["neuron", "trial", "wins"], default="neuron",
                        help="the best neuron (best_by reward, L1584), the highest-reward trial itself, or the success "
                        "neuron that won the most successes (best_by wins)")
    parser.add_argument("--trial", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    args = parser.parse_args()
    given = {k: yaml.safe_load(v) for k, v in (x.split("=", 1) for x in args.trial)}
    trial = dict(CH5, **given)
    overrides = {k: yaml.safe_load(v) for k, v in (x.split("=", 1) for x in args.set)}
    body_params, finish, duration = CASES[args.case]
    seeds = sorted(int(p.name.rsplit("_s", 1)[1]) for p in args.runs.glob(f"{args.start}_adaptive_s*"))
    if not seeds:
        sys.exit(f"{args.runs}: no {args.start}_adaptive_sN run folders (docs/experiments/chapter5.sh makes them)")
    body = Humanoid(Humanoid.Params(duration=duration, finish_line=finish, lane_half_width=0.5,
                                    fall_height_fraction=0.5, fall_angle_deg=45.0, start_noise=0.02))
    body.link = InProcessLink(CPGController(CPGParams(circuit="humanoid_nao", circuit_overrides=overrides)))
    total = 0
    print(f"{args.case}: {args.start}{' -> ' + args.to if args.to else ''}; trial {trial}; circuit {overrides or 'as shipped'}")
    for seed in seeds:
        controller = {**trial, **best(args.runs, args.start, seed, args.point), **given}  # what --trial gives wins
        if args.to:
            nxt = best(args.runs, args.to, seed, args.point)
            controller.update(terrain_switch="gradual", switch_detector="foot_slope", switch_band=1.5,
                              switch_when="outside", **{f"next_{k}": v for k, v in nxt.items()})
        ends = []
        for start in range(args.starts):
            request = TrialRequest(trial_id=start, seed=start, body_params=body_params, controller_params=controller,
                                   log=False)
            result = body.handle(request)
            ends.append(f"{'S' if result.success else 'f'}{result.metrics['time']:.1f}/{result.metrics['distance']:.2f}")
        walked = sum(e[0] == "S" for e in ends)
        total += walked
        print(f"  seed {seed}: {walked}/{args.starts}  {' '.join(ends)}", flush=True)
    print(f"total {total}/{len(seeds) * args.starts}")
    body.close()


if __name__ == "__main__":
    main()
