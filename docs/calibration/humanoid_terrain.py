"""The humanoid across the terrain (issue 29): where the ankle adaptation's numbers in ``humanoid_nao.yaml`` come from.

    python docs/calibration/humanoid_terrain.py [--cases flat ramp10 onto10 ...] [--seeds 4] [--trial KEY=VALUE ...]
                                                 [--set KEY=VALUE ...] [--estimate]

Runs walks of the humanoid (``bodies/humanoid.py``) with the CPG controller in one process (no bus: a calibration, not
an experiment; the experiments are scenarios) and prints, per case, how many seeds succeed and how each failed (the
time, and + / - for a fall forward / backward). ``--trial`` sets the controller's trial parameters (default: the
chapter-5 setting, ``CH5``: the ankle adaptation on, the posture term at 0.1 /s, a 2-s start ramp); ``--set`` overrides
a circuit value by key path (``ankle_adaptation.per_slope_up=-1.5``), as the controller's ``circuit_overrides``. A case
is a ground, a start and a finish line (``CASES``). ``--estimate`` prints, walking the flat and a 10-deg ramp, the
spread of the sensed slope (each foot's estimate after the start, in deg) and of the ankle centres: the flat band of
``terrain.FLOORS`` and the tests.

The numbers it chose (docs/results/chapter5.md, "The ankle adaptation"): per_slope_up, per_slope_down, rate, speed.
About 1-3 s per walk on 2 shared cores.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
from sfl_brain.bodies.humanoid import SENSORS, Humanoid  # noqa: E402
from sfl_brain.body import InProcessLink  # noqa: E402
from sfl_brain.messages import TrialRequest  # noqa: E402
from sfl_brain.modules.controllers.cpg import CPGController, CPGParams  # noqa: E402

#: the chapter-5 setting of the controller (scenarios/e5_learn.yaml's conditions)
CH5 = {"ankle_adaptation": "on", "posture_gain": 0.1, "start_ramp": 2.0}
#: name -> (body trial parameters, finish line m, trial time-out s)
CASES = {
    "flat": ({}, 1.5, 30.0),
    "ramp10": ({"slope_deg": 10.0}, 1.0, 30.0),
    "ramp-10": ({"slope_deg": -10.0}, 1.0, 30.0),
    "ramp11": ({"slope_deg": 11.0}, 1.0, 30.0),
    "onto10": ({"terrain": "1.0:0,4:10"}, 2.0, 40.0),
    "onto11": ({"terrain": "0.5:0,3:11"}, 1.5, 40.0),
    "down_to_flat": ({"terrain": "1.0:-10,4:0"}, 2.5, 40.0),
    "flat_to_down": ({"terrain": "1.0:0,4:-10"}, 2.5, 40.0),
    "up_to_flat": ({"terrain": "1.0:10,4:0"}, 2.5, 40.0),
}
PITCH = [s.name for s in SENSORS].index("torso_pitch")


class Recorder(InProcessLink):
    """The controller in the body's process, keeping each tick's torso pitch and network state."""

    def __init__(self, controller: CPGController) -> None:
        super().__init__(controller)
        self.rows: list[tuple] = []

    def reset(self, msg) -> None:
        self.rows = []
        super().reset(msg)

    def step(self, frame):
        command = super().step(frame)
        network = self.controller.network
        self.rows.append((network.time, frame.values[PITCH], network.slope_estimate, network.ankle_centre))
        return command


def walks(case: str, seeds: int, trial: dict, overrides: dict) -> list[tuple]:
    """Each seed's (success, time s, sign of the final torso pitch, the recorder's rows)."""
    body_params, finish, duration = CASES[case]
    body = Humanoid(Humanoid.Params(duration=duration, finish_line=finish, start_noise=0.02))
    link = Recorder(CPGController(CPGParams(circuit="humanoid_nao", circuit_overrides=overrides)))
    body.link = link
    out = []
    for seed in range(seeds):
        request = TrialRequest(trial_id=seed, seed=seed, body_params=body_params, controller_params=trial, log=False)
        result = body.handle(request)
        out.append((result.success, result.metrics["time"], math.copysign(1, link.rows[-1][1]), link.rows))
    body.close()
    return out


def verdicts(results: list[tuple]) -> str:
    return " ".join("S" if ok else f"f{t:.1f}{'+' if sign > 0 else '-'}" for ok, t, sign, _ in results)


def estimate(trial: dict, overrides: dict, seeds: int) -> None:
    """The spread of the sensed slope and the ankle centres after the start (2 s), flat and 10 deg up (ramp start)."""
    for case in ("flat", "ramp10"):
        slopes, centres = [], []
        for _, _, _, rows in walks(case, seeds, trial, overrides):
            kept = [r for r in rows if r[0] >= 2.0]
            slopes += [r[2] for r in kept]
            centres += [r[3] for r in kept]
        s, c = np.degrees(np.array(slopes)), np.degrees(np.array(centres))
        print(
            f"{case}: slope estimate mean {s.mean():+.2f} deg, s.d. {s.std():.2f}, "
            f"range [{s.min():+.2f}, {s.max():+.2f}]; ankle centre mean {c.mean():+.2f} deg, "
            f"range [{c.min():+.2f}, {c.max():+.2f}]"
        )


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--cases", nargs="+", default=["flat", "ramp10", "ramp-10", "onto10", "down_to_flat"])
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--trial", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--estimate", action="store_true")
    args = parser.parse_args()
    trial = dict(CH5)
    for item in args.trial:
        key, value = item.split("=", 1)
        trial[key] = yaml.safe_load(value)
    trial = {k: v for k, v in trial.items() if v is not None}
    overrides = {}
    for item in args.set:
        key, value = item.split("=", 1)
        overrides[key] = yaml.safe_load(value)
    print(f"trial {trial}; circuit {overrides or 'as shipped'}")
    if args.estimate:
        estimate(trial, overrides, args.seeds)
        return
    for case in args.cases:
        results = walks(case, args.seeds, trial, overrides)
        print(f"{case:14s} {sum(r[0] for r in results)}/{len(results)}  {verdicts(results)}", flush=True)


if __name__ == "__main__":
    main()
