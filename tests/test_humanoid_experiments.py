"""The humanoid's chapter-4 experiments (issue 16): E4.5's return map (docs/experiments/e4_5_poincare.py), the long-walk
ground of the body, and E4.7's push with pattern switching (docs/experiments/e4_7_push.py). Results:
docs/results/chapter4/humanoid.md."""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from sfl_brain.bodies.humanoid import Humanoid
from sfl_brain.body import InProcessLink
from sfl_brain.messages import TrialRequest
from sfl_brain.modules.controllers.cpg import CPGController, CPGParams
from sfl_brain.modules.cpg.patterns import PATTERN_POINTS

EXPERIMENTS = Path(__file__).resolve().parents[1] / "docs" / "experiments"


def load(name: str):
    """A script of docs/experiments as a module (they are not a package)."""
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, EXPERIMENTS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


poincare = load("e4_5_poincare")
push = load("e4_7_push")

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


def test_smoothing_keeps_the_gait_wave_and_removes_impact_spikes():
    t = np.arange(0.0, 10.0, DT)
    slow = 0.05 * np.sin(2 * math.pi * t / 0.667)
    spikes = 0.05 * np.sin(2 * math.pi * 45 * t)  # foot impacts: tens of Hz
    smoothed = poincare.smooth(slow + spikes, DT)
    inner = slice(50, -50)
    assert np.max(np.abs(smoothed - slow)[inner]) < 0.3 * 0.05 + 0.01  # the wave is kept (attenuated, not shifted)
    assert np.max(np.abs(poincare.smooth(spikes, DT))[inner]) < 0.005
    assert poincare.smooth(np.full(50, 2.0), DT) == pytest.approx(2.0)  # the ends average what there is


def test_the_long_walk_ground_and_no_finish_line():
    """With E4.5's body parameters the ground runs 200 m ahead, 100 m behind and 400 m wide; a 4-s walk of the default
    gait neither finishes nor fails, and the pitch rate crosses the section at least once a gait cycle."""
    body = Humanoid(Humanoid.Params(duration=4.0, start_noise=0.02, **poincare.LONG_WALK))
    body.link = InProcessLink(CPGController(CPGParams(circuit="humanoid_nao")))
    walk = poincare.long_walk(3, 0.02, 4.0, body)
    assert body.ground_x[0] == pytest.approx(-100.0) and body.ground_x[-1] == pytest.approx(201.0)
    assert body.ground_boxes[0][1][1] == pytest.approx(200.0)  # half width
    body.close()
    assert walk.ended == "timed out" and walk.t[-1] == pytest.approx(4.0)
    assert len(walk.t) == 400 and np.all(np.isfinite(walk.pitch)) and np.all(np.isfinite(walk.rate))
    times, returns = poincare.section_returns(walk.t, walk.pitch, walk.rate)
    assert len(returns) >= 4  # at least one per 0.667-s cycle after the first second
    assert np.all(np.abs(returns) < 0.5)
    result = poincare.analyse(walk)
    assert np.array_equal(result["returns"], returns)  # E4.5's default: the signals as measured


def test_the_default_ground_is_unchanged():
    body = Humanoid(Humanoid.Params(duration=0.01))
    body.logging = False
    body.start_trial(TrialRequest(trial_id=0, seed=0, body_params={}, controller_params={}, log=False))
    assert body.ground_x[0] == pytest.approx(-1.0) and body.ground_x[-1] == pytest.approx(21.0)
    assert body.ground_boxes[0][1][1] == pytest.approx(1.0)
    body.close()


def test_l1437s_switch_covers_every_joint_with_its_pattern_and_silences_every_coupling():
    params = CPGParams(circuit="humanoid_nao", switch=push.switch_params("time", 9.0))
    entry = params.build_circuit().switches[-1]
    assert len(entry.joints) == 12
    plateau, quiescent = PATTERN_POINTS["plateau"], PATTERN_POINTS["quiescent"]
    for name, rg in entry.joints.items():
        expected = plateau if name.startswith(("shoulder", "knee", "ankle_pitch")) else quiescent
        assert (rg.sigma_s, rg.sigma_f) == expected, name
    assert entry.joint_kicks["hip_pitch_l"] == -entry.joint_kicks["hip_pitch_r"]  # opposite directions (L1437)
    assert entry.joint_kicks["hip_roll_l"] == entry.joint_kicks["hip_roll_r"]  # the same direction
    assert ["hip_pitch_l", "hip_pitch_r"] in entry.inhibit and ["hip_pitch_l", "knee_l"] in entry.inhibit
    other = push.switch_params("time", 9.0, kicks={"knee_l": -1.0})["joint_kicks"]  # --kick knee_l=-1
    assert other["knee_l"] == -1.0 and {k: v for k, v in other.items() if k != "knee_l"} == {
        k: v for k, v in push.KICKS.items() if k != "knee_l"
    }


def test_a_push_moves_the_walking_robot_forward():
    """A 34 N push from behind for 0.1 s at 2 s: 0.3 s later the torso is further forward than without it."""
    body = push.body_for(2.3)
    x = {}
    for force in (34.0, 0.0):
        body.link = InProcessLink(CPGController(CPGParams(circuit="humanoid_nao")))
        pushed = {"push_force": force, "push_duration": 0.1, "push_time": 2.0}
        result = body.handle(TrialRequest(trial_id=0, seed=0, body_params=pushed, controller_params={}, log=False))
        x[force] = result.metrics["distance"]
    body.close()
    assert x[34.0] > x[0.0] + 0.01


@pytest.mark.parametrize("trigger", ["time", "push"])
def test_l1437s_switch_happens_at_the_push_and_not_without_it(trigger):
    """The switch at the push's time, or by the push detector (torso-pitch rate above 1.63 rad/s, E4.7's threshold):
    one switch event of all 12 joints within 0.1 s of the push's start; no push, no detector switch."""
    body = push.body_for(2.3)
    for force in (34.0, 0.0):
        params = push.switch_params("time", 2.0) if trigger == "time" else push.switch_params("push", 0.0, 1.63)
        controller = CPGController(CPGParams(circuit="humanoid_nao", switch=params))
        result = push.trial(body, controller, 0, {"push_force": force, "push_duration": 0.1, "push_time": 2.0})
        events = controller.network.switch_events
        if force == 0.0 and trigger == "push":
            assert events == [] and result["switch"] is None
            continue
        [event] = events
        assert 2.0 <= event.time <= 2.1
        assert set(event.patterns) == set(push.KICKS)
        assert result["jump"] is not None and result["jump"][0] > 0  # measured, as E4.7 prints it
    body.close()


def test_a_continuous_switch_keeps_every_command_at_its_angle_on_the_switch_tick():
    body = push.body_for(2.1)
    switch = push.switch_params("time", 2.0, theta0="continuous")
    controller = CPGController(CPGParams(circuit="humanoid_nao", switch=switch))
    result = push.trial(body, controller, 0, {})
    body.close()
    assert result["switch"] == pytest.approx(2.0)
    assert result["jump"][0] < 1e-9 < result["jump"][2]  # no jump at the switch; walking, a gap the tick before
