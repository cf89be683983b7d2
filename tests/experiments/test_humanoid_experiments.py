"""The humanoid's chapter-4 experiments as scenarios (issue 23): E4.5's return map (sfl_brain/report/poincare.py, on the
walks of scenarios/e4_5_poincare.yaml), the long-walk ground of its body, and E4.7's switch (scenarios/e4_7_push.yaml)
fired by the body's touch sensor. Results: docs/results/chapter4/."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sfl_brain.bodies.humanoid import JOINT_NAMES, Humanoid
from sfl_brain.body import InProcessLink
from sfl_brain.messages import TrialRequest
from sfl_brain.modules.controllers.cpg import CPGController
from sfl_brain.modules.cpg.patterns import PATTERN_POINTS
from sfl_brain.report import poincare
from sfl_brain.scenario import load

from ..conftest import SCENARIOS

DT = 0.01


def damped(centre: float, amplitude: float, decay: float, period: float, seconds: float = 30.0):
    """centre + amplitude e^(-decay t) cos(2 pi t / period), its exact rate, on a 10-ms grid."""
    t = np.arange(0.0, seconds, DT)
    w = 2 * math.pi / period
    envelope = amplitude * np.exp(-decay * t)
    angle = centre + envelope * np.cos(w * t)
    rate = envelope * (-decay * np.cos(w * t) - w * np.sin(w * t))
    return t, angle, rate


@pytest.mark.parametrize("sign", [-1, 1])
def test_a_damped_oscillation_has_its_centre_as_fixed_point_and_its_decay_per_cycle_as_slope(sign):
    """The maxima (sign -1) or minima (+1) of centre + A e^(-lambda t) cos(w t) approach the centre geometrically,
    by e^(-lambda T) per cycle T: the map r_{n+1} = c (1 - q) + q r_n, fixed point c, slope q."""
    t, angle, rate = damped(0.046, 0.2, 0.3, 0.667)
    times, returns = poincare.section_returns(t, angle, rate, sign)
    assert len(returns) == pytest.approx(30 / 0.667, abs=1.5)  # one crossing per cycle
    assert np.diff(times) == pytest.approx(0.667, abs=0.01)
    fit = poincare.fit_return_map(returns[:12])  # before the envelope drowns in the interpolation error
    assert fit.fixed_point == pytest.approx(0.046, abs=1e-3)
    assert fit.slope == pytest.approx(math.exp(-0.3 * 0.667), abs=2e-3)
    assert fit.stable
    assert np.all(np.sign(returns - 0.046) == -sign)  # maxima above the centre, minima below


def test_a_growing_oscillation_gives_an_unstable_map():
    t, angle, rate = damped(0.0, 0.01, -0.2, 0.667, seconds=10.0)
    fit = poincare.fit_return_map(poincare.section_returns(t, angle, rate)[1])
    assert fit.slope == pytest.approx(math.exp(0.2 * 0.667), abs=5e-3)
    assert not fit.stable


def test_a_map_needs_three_returns():
    with pytest.raises(ValueError, match="expected at least 3 returns to fit a map; got 2"):
        poincare.fit_return_map(np.array([0.1, 0.2]))


def plan_parts(name: str, *sets: str):
    """A scenario's body (its parameters as the run builds them) and a fresh controller of it, in one process."""
    plan = load(SCENARIOS / f"{name}.yaml", list(sets))
    body_spec = next(i for i in plan.instances if i.name in plan.bodies)
    controller_spec = next(i for i in plan.instances if i.spec_name == "controller")
    body = Humanoid(Humanoid.Params(**body_spec.params))
    body.logging = False
    return plan, body, lambda: CPGController(CPGController.Params(**controller_spec.params))


def test_e4_5s_long_walk_ground_has_no_finish_line_in_reach():
    """With E4.5's body parameters the ground runs 200 m ahead, 100 m behind and 400 m wide; a 4-s walk of the default
    gait neither finishes nor fails."""
    _, body, controller = plan_parts("e4_5_poincare", "modules.body.params.duration=4")
    body.link = InProcessLink(controller())
    result = body.handle(TrialRequest(trial_id=0, seed=3, body_params={}, controller_params={}, log=False))
    assert body.ground_x[0] == pytest.approx(-100.0) and body.ground_x[-1] == pytest.approx(201.0)
    assert body.ground_boxes[0][1][1] == pytest.approx(200.0)  # half width
    body.close()
    assert result.metrics["timed_out"] and result.metrics["time"] == pytest.approx(4.0)


def test_the_default_ground_is_unchanged():
    body = Humanoid(Humanoid.Params(duration=0.01))
    body.logging = False
    body.start_trial(TrialRequest(trial_id=0, seed=0, body_params={}, controller_params={}, log=False))
    assert body.ground_x[0] == pytest.approx(-1.0) and body.ground_x[-1] == pytest.approx(21.0)
    assert body.ground_boxes[0][1][1] == pytest.approx(1.0)
    body.close()


def test_l1437s_switch_covers_every_joint_with_its_pattern_and_silences_every_coupling():
    _, _, controller = plan_parts("e4_7_push")
    entry = next(s for s in controller().circuit.switches if s.name == "reaction")
    assert len(entry.joints) == 12 and entry.theta0 == "continuous" and entry.input == "back"
    plateau, quiescent = PATTERN_POINTS["plateau"], PATTERN_POINTS["quiescent"]
    for name, rg in entry.joints.items():
        expected = plateau if name.startswith(("shoulder", "knee", "ankle_pitch")) else quiescent
        assert (rg.sigma_s, rg.sigma_f) == expected, name
    assert entry.joint_kicks["hip_pitch_l"] == -entry.joint_kicks["hip_pitch_r"]  # opposite directions (L1437)
    assert entry.joint_kicks["hip_roll_l"] == entry.joint_kicks["hip_roll_r"]  # the same direction
    coupled = {tuple(sorted({c.source.split(".")[0], c.target.split(".")[0]})) for c in controller().circuit.couplings}
    assert {tuple(sorted(pair)) for pair in entry.inhibit} == {pair for pair in coupled if len(pair) == 2}
    angle = next(s for s in controller().circuit.switches if s.name == "reaction_angle")
    assert angle.theta0 == "angle" and angle.joints == entry.joints  # the same switch, the 2017 scripts' theta_0


def run_pushed(body, make, force: float, switch: str) -> tuple[CPGController, list]:
    """One 2.3-s trial of the E4.7 scenario's controller with a push at 2 s; (the controller, per tick: the command
    minus the measured angles)."""
    controller = make()
    body.link = InProcessLink(controller)
    gaps = []
    original = body.actuate
    body.actuate = lambda command: (gaps.append(np.asarray(command) - body.q), original(command))
    try:
        pushed = {"push_force": force, "push_duration": 0.1, "push_time": 2.0}
        body.handle(
            TrialRequest(trial_id=0, seed=0, body_params=pushed, controller_params={"switch": switch}, log=False)
        )
    finally:
        body.actuate = original
    return controller, gaps


def test_the_switch_comes_the_tick_after_the_push_touches_and_never_without_it():
    _, body, make = plan_parts("e4_7_push", "modules.body.params.duration=2.3")
    controller, _ = run_pushed(body, make, 0.0, "reaction")
    assert controller.network.switch_events == []  # walking never presses on the back
    controller, gaps = run_pushed(body, make, 34.0, "reaction")
    [event] = controller.network.switch_events
    assert event.time == pytest.approx(2.01) and set(event.patterns) == set(JOINT_NAMES)
    tick = round(event.time / DT)
    assert np.abs(gaps[tick]).max() < 1e-9 < np.abs(gaps[tick - 1]).max()  # theta0 continuous: no command jumps
    controller, gaps = run_pushed(body, make, 34.0, "reaction_angle")
    assert np.abs(gaps[tick]).max() > 0.3  # theta_0 := angle: the reflexes' offset makes the commands jump
    body.close()


def test_a_push_moves_the_walking_robot_forward():
    """A 34 N push from behind for 0.1 s at 2 s: 0.3 s later the torso is further forward than without it."""
    _, body, make = plan_parts("e4_7_push", "modules.body.params.duration=2.3")
    x = {}
    for force in (34.0, 0.0):
        body.link = InProcessLink(make())
        pushed = {"push_force": force, "push_duration": 0.1, "push_time": 2.0}
        result = body.handle(TrialRequest(trial_id=0, seed=0, body_params=pushed, controller_params={}, log=False))
        x[force] = result.metrics["distance"]
    body.close()
    assert x[34.0] > x[0.0] + 0.01
