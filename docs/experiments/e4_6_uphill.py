"""E4.6 (L1417-1426): the humanoid's CPG gait up an 11-degree slope, with the descending control (alpha_MLR, theta_MLR).

    python docs/experiments/e4_6_uphill.py [--seeds 3] [--slope 11]

The thesis climbs 11 degrees with "periodic patterns", the amplitude set by the PF slope alpha_MLR = -0.2 and the
centre of oscillation by theta_MLR = 0.15 (L1419), frequency by sigma_s, sigma_f; it gives no other number. Here the
default gait of ``modules/cpg/circuits/humanoid_nao.yaml`` (flat ground, tests/test_humanoid_walk.py) is given
(alpha_MLR, theta_MLR) as the CPG controller's trial parameters, on every joint (as (4.9) on every PF; theta_MLR with
the signs of digest §7.6: + = extensor domination), and the body starts standing on the ramp (its ankles pitched by
the slope, bodies/humanoid.py). A trial succeeds when the torso crosses x = 1.5 m (L1650), within 40 s.

The script prints, as Markdown:

1. the default gait (1, 0) and the thesis's values (-0.2, 0.15) on the slope and on the flat;
2. a grid around the thesis's values, alpha_MLR -0.4..0 x theta_MLR 0.05..0.25;
3. a grid where this circuit climbs, alpha_MLR 0.8..1.2 x theta_MLR -1.8..-1.2 (found by a coarse search over
   alpha_MLR -0.2..1.5 x theta_MLR -2..1 while this script was written; that search is not part of it);

each cell ``k/n`` = successes over ``--seeds`` seeds (the body's ``start_noise`` 0.02 rad), with the mean time of the
successes. Controller and body in one process. About 40 s on 2 quiet cores (149 s at load average 5-6). Results:
docs/results/chapter4/humanoid.md.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
from sfl_brain.bodies.humanoid import Humanoid  # noqa: E402
from sfl_brain.body import InProcessLink  # noqa: E402
from sfl_brain.messages import TrialRequest  # noqa: E402
from sfl_brain.modules.controllers.cpg import CPGController, CPGParams  # noqa: E402

THESIS = (-0.2, 0.15)  # (alpha_MLR, theta_MLR), L1419
AROUND_THESIS = (np.round(np.linspace(-0.4, 0.0, 5), 3), np.round(np.linspace(0.05, 0.25, 5), 3))
CLIMBING = (np.round(np.linspace(0.8, 1.2, 5), 3), np.round(np.linspace(-1.8, -1.2, 5), 3))


class Trials:
    """The humanoid and the default-gait CPG in one process; ``run`` gives (successes, mean time, outcomes)."""

    def __init__(self, seeds: int) -> None:
        self.body = Humanoid(Humanoid.Params(duration=40.0, start_noise=0.02))
        self.body.link = InProcessLink(CPGController(CPGParams(circuit="humanoid_nao")))
        self.seeds = seeds
        self.n = 0

    def run(self, alpha_mlr: float, theta_mlr: float, slope: float) -> tuple[int, float, list[str]]:
        times, outcomes = [], []
        for seed in range(self.seeds):
            request = TrialRequest(
                trial_id=self.n,
                seed=seed,
                body_params={"slope_deg": slope},
                controller_params={"alpha_mlr": float(alpha_mlr), "theta_mlr": float(theta_mlr)},
                log=False,
            )
            self.n += 1
            result = self.body.handle(request)
            m = result.metrics
            if result.success:
                times.append(m["time"])
                outcomes.append(f"W {m['time']:.1f} s, eta {result.quality:.5f}")
            else:
                why = "fell" if m["fell"] else "left the lane" if m["left_lane"] else "timed out"
                outcomes.append(f"{why} at {m['time']:.1f} s, x {m['distance']:+.2f} m")
        return len(times), float(np.mean(times)) if times else float("nan"), outcomes

    def grid(self, alphas, thetas, slope: float) -> None:
        print(f"| alpha_MLR \\ theta_MLR | {' | '.join(f'{t:g}' for t in thetas)} |")
        print(f"|---|{'---|' * len(thetas)}")
        for a in alphas:
            cells = []
            for t in thetas:
                k, mean, _ = self.run(a, t, slope)
                cells.append(f"{k}/{self.seeds}" + (f" ({mean:.1f} s)" if k else ""))
            print(f"| {a:g} | {' | '.join(cells)} |")


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--slope", type=float, default=11.0, help="deg, uphill + (L1417: 11)")
    args = parser.parse_args()
    trials = Trials(args.seeds)
    print(f"### 1. The default gait and the thesis's descending control, {args.slope:g} deg and flat\n")
    print("| (alpha_MLR, theta_MLR) | slope deg | successes | trials |")
    print("|---|---|---|---|")
    best = (float(CLIMBING[0][2]), float(CLIMBING[1][2]))  # (1.0, -1.5): the middle of the climbing band
    for point in ((1.0, 0.0), THESIS, best):
        for slope in (args.slope, 0.0):
            k, _, outcomes = trials.run(*point, slope)
            print(f"| ({point[0]:g}, {point[1]:g}) | {slope:g} | {k}/{args.seeds} | {'; '.join(outcomes)} |")
    print(f"\n### 2. Around the thesis's values (L1419), {args.slope:g} deg\n")
    trials.grid(*AROUND_THESIS, args.slope)
    print(f"\n### 3. Where this circuit climbs, {args.slope:g} deg\n")
    trials.grid(*CLIMBING, args.slope)
    trials.body.close()


if __name__ == "__main__":
    main()
