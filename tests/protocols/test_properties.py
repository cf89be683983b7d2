"""Properties of the whole learning cycle on the analytic body, over several seeds.

The analytic body's viable region is a disc (centre 0.5, 0.5, radius 0.3: 28% of the unit
square) and its quality field a Gaussian bump at (0.6, 0.6) inside it, so every claim can be
checked against ground truth. The protocol is the one ``sfl run`` runs; it is hosted in one
process here (``run_local``) for speed; ``test_e2e`` shows that the processes-over-Zenoh run
gives identical records.
"""

import math

import numpy as np
import pytest

from sfl_brain.protocols.local import run_local
from sfl_brain.scenario import load

from ..conftest import SCENARIOS

SCENARIO = SCENARIOS / "analytic_learn.yaml"
CENTRE, RADIUS, PEAK, WIDTH = np.array([0.5, 0.5]), 0.3, np.array([0.6, 0.6]), 0.15
SEEDS = range(4)


def learn(overrides, seed, run_dir=None):
    plan = load(SCENARIO, overrides, seed=seed)
    rows = run_local(plan, run_dir=run_dir, through_codec=False)
    return [r for r in rows if r["kind"] == "trial"], [r for r in rows if r["kind"] == "decision"]


def inside(points):
    return np.linalg.norm(np.asarray(points) - CENTRE, axis=-1) <= RADIUS


def eta(points):
    points = np.asarray(points)
    return np.where(inside(points), np.exp(-np.sum((points - PEAK) ** 2, axis=-1) / (2 * WIDTH**2)), 0.0)


def test_success_rate_falls_with_vigilance_as_in_fig_3_13():
    """Pooled over seeds: the rate of succeeded trials falls as s_vig falls from 0.05 to -0.4."""
    rates = {}
    for s_vig in (0.05, 0.0, -0.1, -0.2, -0.4):
        outcomes = []
        for seed in SEEDS:
            trials, _ = learn(
                [
                    f"modules.vigilance.params.value={s_vig}",
                    "protocol.trials=150",
                    "protocol.max_decisions=20000",
                ],
                seed,
            )
            outcomes += [t["success"] for t in trials]
        rates[s_vig] = float(np.mean(outcomes))
    # cautious zone well above the region's share of the square (0.28), risky zone near it
    assert min(rates[0.05], rates[0.0]) >= 0.75, rates
    assert rates[0.0] > rates[-0.1] > rates[-0.2] > rates[-0.4], rates
    assert rates[-0.4] < 0.40, rates


def test_no_trial_well_above_and_every_sample_accepted_well_below():
    _, decisions = learn(["modules.vigilance.params.value=0.6", "protocol.trials=5", "protocol.max_decisions=3000"], 0)
    assert len(decisions) == 3000 and not any(d["go"] for d in decisions)
    trials, decisions = learn(["modules.vigilance.params.value=-1.0", "protocol.trials=100"], 0)
    assert len(trials) == 100 and len(decisions) == 100 and all(d["go"] for d in decisions)


@pytest.mark.parametrize("seed", range(3))
def test_success_map_settles_inside_the_region_and_failure_map_outside(tmp_path, seed):
    """Risky vigilance (many failures learnt, as in the thesis's s_vig = -0.2 case), 500 trials."""
    learn(["modules.vigilance.params.value=-0.2", "protocol.trials=500"], seed, tmp_path)
    with np.load(tmp_path / "acc.npz") as maps:
        success = maps["success_weights"]
        failure = maps["failure_weights"][maps["failure_active"]]
    assert inside(success).mean() >= 0.95
    assert (~inside(failure)).mean() >= 0.75


def test_qarl_puts_success_neurons_where_eta_is_higher(tmp_path):
    """Mean eta at the success map's neurons with QARL (5.1)-(5.3) over without: a ratio above 1."""
    ratios = []
    for seed in SEEDS:
        means = []
        for enabled in ("true", "false"):
            run_dir = tmp_path / f"qarl-{seed}-{enabled}"
            learn(
                [
                    "modules.vigilance.params.value=-0.1",
                    "protocol.trials=300",
                    f"modules.ofc.params.enabled={enabled}",
                ],
                seed,
                run_dir,
            )
            with np.load(run_dir / "acc.npz") as maps:
                means.append(eta(maps["success_weights"]).mean())
        ratios.append(means[0] / means[1])
    assert min(ratios) > 1.05 and np.median(ratios) > 1.2, ratios


def test_adaptive_vigilance_brings_ns_over_nf_toward_one_within_100_trials():
    blind = []
    for seed in SEEDS:
        adaptive, _ = learn(
            [
                "modules.vigilance.params.mode=adaptive",
                "modules.vigilance.params.value=0.0",
                "protocol.trials=100",
            ],
            seed,
        )
        accept_all, _ = learn(["modules.vigilance.params.value=-1.0", "protocol.trials=100"], seed)
        assert abs(math.log(adaptive[-1]["ns_nf"])) <= math.log(1.6), (seed, adaptive[-1]["ns_nf"])
        blind.append(accept_all[-1]["ns_nf"])
    assert np.median(blind) < 0.6, blind  # blind sampling: the disc's 28% share gives about 0.4


def test_batch_size_is_only_a_speed_knob():
    """Candidates are one seeded stream; how many ACC evaluates per request changes no record."""

    def stable(rows):
        return [{k: v for k, v in r.items() if k not in ("wall_ms", "cpu_body_s", "cpu_controller_s")} for r in rows]

    one = run_local(load(SCENARIO, ["protocol.batch=1", "protocol.trials=80", "modules.vigilance.params.value=-0.1"]))
    many = run_local(
        load(SCENARIO, ["protocol.batch=512", "protocol.trials=80", "modules.vigilance.params.value=-0.1"])
    )
    assert stable(one) == stable(many) and len(one) > 80
