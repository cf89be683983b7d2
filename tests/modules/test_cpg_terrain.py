"""Across the terrain (issue 29): the ankles' centres follow the slope the feet sense (modules/cpg/adaptation.py,
circuit key ``ankle_adaptation``; L1417, L1737, L1764), a terrain switch lands on the learnt gait with every command
continuous (L1766), and the detectors that sense a change of terrain (modules/cpg/terrain.py; L1759).

Most of it is driven by hand (scripted sensor frames, no physics: what the feet and the inertial sensor would report
standing on a given slope), so that each property is exact and cheap; two short walks of the real humanoid check the
adaptation where it matters."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sfl_brain.bodies.humanoid import Humanoid
from sfl_brain.bodies.humanoid_table import STANDING
from sfl_brain.body import InProcessLink
from sfl_brain.messages import TrialRequest
from sfl_brain.modules.controllers.cpg import CPGController, CPGParams, terrain_switch_text
from sfl_brain.modules.cpg import CPGNetwork, load_circuit, validate_circuit
from sfl_brain.modules.cpg.circuit import read_circuit_data
from sfl_brain.scenario import ScenarioError

from .test_cpg_controller import scenario_problems, start, tick

DT = 0.01
SLOPE = math.radians(10.0)  # §5.7's slopes
FLAT_NEURON = {"gain_pitch": 1.18, "gain_roll": 0.91, "sigma_s": 4.87}  # a flat map's best neuron, say
UPHILL_NEURON = {"gain_pitch": 1.06, "gain_roll": 1.69, "sigma_s": 4.9}  # an uphill map's
ADAPT = {"ankle_adaptation": "on"}


def controller(**params) -> CPGController:
    return CPGController(CPGParams(circuit="humanoid_nao", **params))


def standing_on(reads: list[str], slope: float, heel: float = 25.0, toe: float = 25.0, noise=None) -> np.ndarray:
    """The sensor frame of the humanoid standing with both soles flat on ground sloping ``slope`` rad (uphill +): the
    standing pose with the ankles pitched by -slope (as the body starts on a ramp), the torso at the pose's lean, both
    feet pressing with ``heel`` and ``toe`` N. ``noise``: rad added to the left ankle's angle (its sole then sits
    tilted by as much)."""
    frame = np.zeros(len(reads))
    for name, angle in STANDING.items():
        frame[reads.index(name)] = angle - (slope if name.startswith("ankle_pitch") else 0.0)
    if noise is not None:
        frame[reads.index("ankle_pitch_l")] += noise
    frame[reads.index("torso_pitch")] = -(STANDING["hip_pitch_l"] + STANDING["knee_l"] + STANDING["ankle_pitch_l"])
    for name, force in (("heel_l", heel), ("toe_l", toe), ("heel_r", heel), ("toe_r", toe)):
        frame[reads.index(name)] = force
    return frame


def ankles(c: CPGController) -> np.ndarray:
    network = c.network
    joints = [network.circuit.joint_index(name) for name in ("ankle_pitch_l", "ankle_pitch_r")]
    return network.theta0[0, joints]


# ------------------------------------------------------------------------------------------ the sensed slope


def test_standing_flat_on_a_slope_the_feet_sense_it_and_the_ankles_take_it_at_the_first_tick():
    spec = load_circuit("humanoid_nao").ankle_adaptation
    for slope in (SLOPE, -SLOPE, 0.0):
        c = controller()
        reads, _ = start(c, params=ADAPT)
        tick(c, standing_on(reads, slope), 0)
        np.testing.assert_allclose(c.network.slope_estimate, [slope, slope], atol=1e-12)
        per_slope = spec.per_slope_up if slope > 0 else spec.per_slope_down
        np.testing.assert_allclose(c.network.ankle_centre, [per_slope * slope] * 2, atol=1e-12)


def test_the_estimate_follows_flat_stance_only_and_the_centre_moves_at_most_its_speed():
    """Flat first, then (at 1 s) the soles lie on a 10-deg ramp: the estimate follows at ``rate``, the centre at most
    ``speed`` rad/s toward per_slope_up x the estimate; a foot pressing with its heel only senses nothing itself and
    aims at the ground the other senses."""
    spec = load_circuit("humanoid_nao").ankle_adaptation
    c = controller()
    reads, _ = start(c, params=ADAPT)
    centres, estimates = [], []
    for t in range(200):
        frame = standing_on(reads, 0.0 if t < 100 else SLOPE)
        if t >= 100:
            frame[reads.index("toe_r")] = 0.0  # the right foot on its heel: not lying on the ground
        tick(c, frame, t)
        centres.append(c.network.ankle_centre)
        estimates.append(c.network.slope_estimate)
    centres, estimates = np.array(centres), np.array(estimates)
    np.testing.assert_allclose(estimates[:100], 0.0, atol=1e-12)
    assert abs(estimates[-1, 0] - SLOPE) < 1e-3  # rate 30 /s: within 1e-3 well before 1 s
    np.testing.assert_allclose(estimates[100:, 1], 0.0, atol=1e-12)  # heel only: nothing sensed
    assert np.max(np.abs(np.diff(centres[:, 0]))) <= spec.speed * DT + 1e-12
    assert centres[-1, 0] == pytest.approx(spec.per_slope_up * estimates[-1, 0], abs=1e-9)
    # on its heel, not lying flat: it aims at the ground the left foot senses (it rolls onto the same slope)
    assert centres[-1, 1] == pytest.approx(centres[-1, 0], abs=1e-12)


def test_a_foot_in_the_air_aims_at_the_slope_the_other_stands_on():
    c = controller()
    reads, _ = start(c, params=ADAPT)
    for t in range(100):
        frame = standing_on(reads, SLOPE)
        if t >= 1:  # after the start, the right foot lifts: it aims where the left one stands
            for name in ("heel_r", "toe_r"):
                frame[reads.index(name)] = 0.0
            frame[reads.index("ankle_pitch_r")] += 0.3  # and its own sole's pitch says nothing of the ground
        tick(c, frame, t)
    np.testing.assert_allclose(c.network.ankle_centre[1], c.network.ankle_centre[0], atol=1e-12)


def test_off_or_without_the_key_nothing_moves():
    c = controller()
    reads, _ = start(c)  # the circuit's own: enabled false
    theta0 = c.network.theta0.copy()
    for t in range(50):
        tick(c, standing_on(reads, SLOPE), t)
    np.testing.assert_array_equal(c.network.theta0, theta0)
    data = read_circuit_data("humanoid_nao")
    del data["ankle_adaptation"]
    network = CPGNetwork(validate_circuit(data))
    with pytest.raises(ValueError, match="ankle_adaptation: circuit humanoid_nao has none"):
        network.set_ankle_adaptation(True)


# ------------------------------------------------------------------------------------------ the switch (L1766)


def switching_walk(mode: str, ramp_at: int = 200, ticks: int = 500) -> CPGController:
    """The flat neuron on flat ground; at 1 s (a time-triggered switch) it moves to the uphill neuron; at 2 s the soles
    lie on the 10-deg ramp."""
    c = controller(terrain_switch_after=1.0)
    params = {**ADAPT, **FLAT_NEURON, "terrain_switch": mode, "switch_detector": "time",
              **{f"next_{k}": v for k, v in UPHILL_NEURON.items()}}  # fmt: skip
    reads, _ = start(c, params=params)
    for t in range(ticks):
        tick(c, standing_on(reads, 0.0 if t < ramp_at else SLOPE), t)
    return c


def test_a_gradual_switch_keeps_every_command_continuous_and_lands_on_the_ramp_starts_gait():
    """Issue 29's item 1: the gait reached by a switch and the same neuron started on the ramp have the same ankle
    centres (within 0.02 rad) and gains; the switch changes no command by more than 0.02 rad in a tick (measured as what
    the switch itself adds to a tick's command), where at once it jumps."""
    switched = switching_walk("gradual")
    [event] = switched.network.terrain_switch_events
    assert event.detector == "time" and event.time == pytest.approx(1.0)
    text = terrain_switch_text(event)
    assert text.startswith("terrain switch (gradually over 0.667 s): at 1 s (switch_detector time);")
    jumps = np.array([j for _, j in switched.network.terrain_switch_jumps])
    assert len(jumps) == int(round(0.667 / DT)) + 1 and jumps.max() < 0.02
    at_once = switching_walk("at_once")
    assert max(j for _, j in at_once.network.terrain_switch_jumps) > 0.02  # the measure sees a jump (0.032 rad)
    ramp_start = controller()
    reads, _ = start(ramp_start, params={**ADAPT, **UPHILL_NEURON})
    for t in range(300):
        tick(ramp_start, standing_on(reads, SLOPE), t)
    np.testing.assert_allclose(ankles(switched), ankles(ramp_start), atol=0.02)
    np.testing.assert_allclose(switched.network.gain, ramp_start.network.gain, rtol=1e-12)
    assert switched.network.sigma_s[0, 0] == pytest.approx(UPHILL_NEURON["sigma_s"])


# ------------------------------------------------------------------------------------------ the detectors (L1759)


def scripted_ramp(c: CPGController, reads: list[str], ramp_at: float, seconds: float, seed: int = 0) -> None:
    """Flat stance with the left ankle's and the torso's readings jittered (0.5 deg s.d. each), then from ``ramp_at`` s
    the left sole lies on a 10-deg ramp (the front foot meets it)."""
    rng = np.random.default_rng(seed)
    for t in range(int(round(seconds / DT))):
        frame = standing_on(reads, 0.0, noise=rng.normal(0.0, math.radians(0.5)))
        frame[reads.index("torso_pitch")] += rng.normal(0.0, math.radians(0.5))  # the inertial sensor's jitter
        if t * DT >= ramp_at:
            frame[reads.index("ankle_pitch_l")] -= SLOPE
        tick(c, frame, t)


def test_the_foot_slope_detector_fires_within_its_latency_on_a_scripted_ramp_and_not_before():
    c = controller(terrain_watch=["foot_slope", "torso"])
    params = {**ADAPT, "terrain_switch": "at_once", "switch_detector": "foot_slope", "switch_band": 1.5,
              "switch_when": "outside", "next_gain_pitch": 1.0}  # fmt: skip
    reads, _ = start(c, params=params)
    scripted_ramp(c, reads, ramp_at=6.0, seconds=7.0)
    [event] = c.network.terrain_switch_events
    assert event.detector == "foot_slope" and 6.0 <= event.time <= 6.0 + 0.5  # issue 29: within 0.5 s
    assert terrain_switch_text(event).startswith("terrain switch (at once): foot_slope ")
    assert event.threshold[1] - event.threshold[0] >= 2 * 0.035 - 1e-12  # never narrower than its floor
    watched = {e.detector: e for e in c.network.detector_events}
    assert watched["foot_slope"].time == event.time
    assert "torso" not in watched  # the torso's pitch did not change: the thesis's detector cannot see this


@pytest.mark.parametrize("floor", [0.0524, 0.2])
def test_the_trials_foot_slope_floor_is_the_bands_narrowest_half_for_the_switch_and_the_watch(floor):
    c = controller(terrain_watch=["foot_slope"])
    params = {**ADAPT, "terrain_switch": "at_once", "switch_detector": "foot_slope", "switch_band": 1.5,
              "switch_when": "outside", "next_gain_pitch": 1.0, "foot_slope_floor": floor}  # fmt: skip
    reads, _ = start(c, params=params)
    scripted_ramp(c, reads, ramp_at=6.0, seconds=7.0)
    watched = {e.detector: e for e in c.network.detector_events}
    if floor > SLOPE:  # wider than the ramp's 10 deg: the ramp stays inside it
        assert c.network.terrain_switch_events == [] and watched == {}
        return
    [event] = c.network.terrain_switch_events
    assert 6.0 <= event.time <= 6.0 + 0.5
    assert event.threshold[1] - event.threshold[0] == pytest.approx(2 * floor)  # the jitter's range is narrower
    assert watched["foot_slope"].time == event.time


def test_a_detector_needs_what_it_reads_and_a_measured_band():
    c = controller()
    for params, message in [
        ({"terrain_switch": "at_once", "switch_detector": "foot_slope", "switch_threshold": 0.1,
          "switch_when": "above", "next_gain_pitch": 1.0},
         "switch_detector 'foot_slope': expected switch_band (its band measured on the walk)"),
        ({"terrain_switch": "at_once", "switch_detector": "time", "switch_band": 1.5, "next_gain_pitch": 1.0},
         "switch_detector 'time': expected no switch_threshold or switch_band (it senses nothing)"),
        ({"switch_detector": "foot_slop"}, "switch_detector: expected one of ['torso', 'pitch_rate', 'phase_pitch', "
         "'foot_slope', 'ankle_error', 'time']; got 'foot_slop' (did you mean 'foot_slope'?)"),
        ({"ankle_adaptation": "onn"},
         "ankle_adaptation: expected one of ['on', 'off']; got 'onn' (did you mean 'on'?)"),
        ({"start_ramp": -1.0}, "start_ramp: expected a time in s >= 0; got -1.0"),
        ({"foot_slope_floor": -0.1}, "foot_slope_floor: expected a half band in rad within [0, pi/2]; got -0.1"),
        ({"foot_slope_floor": 0.05, "terrain_switch": "at_once", "switch_detector": "torso", "switch_band": 1.5,
          "switch_when": "outside", "next_gain_pitch": 1.0},
         "foot_slope_floor: expected the feet's slope detector watched this trial (switch_detector foot_slope, or "
         "foot_slope in the module's terrain_watch); it is not"),
        ({"ankle_adaptation": "on", "start_slope_deg": 10.0},
         "start_slope_deg: expected none with ankle_adaptation 'on' (the adaptation senses the slope the trial starts "
         "on); got both"),
    ]:  # fmt: skip
        with pytest.raises(ValueError) as err:
            start(c, params=params)
        assert str(err.value) == message
    [line] = scenario_problems({"circuit": "humanoid_nao", "terrain_watch": ["foot_slop"]})
    assert line.startswith("s.yaml: modules.controller.params.terrain_watch.0: ")
    assert "'foot_slope'" in line


def test_the_circuit_keys_name_what_exists():
    data = read_circuit_data("humanoid_nao")
    data["ankle_adaptation"]["feet"]["ankle_pitch_l"]["heel"] = "GB_left"
    data["ankle_adaptation"]["feet"]["ankle_pitch_r"]["chain"][0] = "hip_pich_r"
    data["posture"]["relative_sensors"] = ["FX"]
    with pytest.raises(ScenarioError) as err:
        validate_circuit(data, "c.yaml")
    text = str(err.value)
    assert "ankle_adaptation.feet.ankle_pitch_l.heel: expected one of the sensory neurons" in text
    assert "got 'GB_left' (did you mean `GB_l`?)" in text
    assert "ankle_adaptation.feet.ankle_pitch_r.chain.0: expected one of the inputs" in text
    assert "posture.relative_sensors.0: expected one of the sensory neurons" in text


# ------------------------------------------------------------------------------------------ start ramp, posture


def test_the_start_ramp_grows_alpha_mlr_from_zero_then_leaves_the_pf_exactly_as_without():
    ramped, plain = controller(), controller()
    reads, _ = start(ramped, params={"start_ramp": 1.0})
    start(plain)
    frame = standing_on(reads, 0.0)
    full = plain.network._pf_half_slope.copy()
    for t in range(150):
        tick(ramped, frame, t)
        share = min(1.0, (t + 1) * DT / 1.0)
        np.testing.assert_allclose(ramped.network._pf_half_slope, share * full, rtol=1e-12)
    np.testing.assert_array_equal(ramped.network._pf_half_slope, full)


def test_the_fall_sensors_are_relative_to_the_held_lean_while_the_posture_term_is_on():
    c = controller()
    network = c.network
    fb, ff = network.sensor_names.index("FB"), network.sensor_names.index("FF")
    start(c, params={"posture_gain": 0.0})
    np.testing.assert_array_equal(network._sensor_theta[[fb, ff]], [-0.1, 0.1])
    start(c, params={"posture_gain": 0.1})
    np.testing.assert_allclose(network._sensor_theta[[fb, ff]], [-0.1 + 0.1745, 0.1 + 0.1745], atol=1e-12)


def test_the_posture_term_integrates_the_lean_averaged_over_its_window():
    """The torso pitch swinging +-0.2 rad at 1.5 Hz about 0.05 rad past the target: over whole windows the shift moves
    by gain x 0.05 x t, the swing averaged out."""
    c = controller()
    reads, _ = start(c, params={"posture_gain": 0.5})
    frame = np.zeros(len(reads))
    shifts = []
    for t in range(300):
        frame[reads.index("torso_pitch")] = 0.1745 + 0.05 + 0.2 * math.sin(2 * math.pi * 1.5 * t * DT)
        tick(c, frame, t)
        shifts.append(c.network.posture_shift[0])
    per_tick = np.diff(shifts[100:])  # whole windows from 0.67 s on
    np.testing.assert_allclose(per_tick, 0.5 * 0.05 * DT, rtol=0.02)  # the swing (0.2 rad) averaged out


# ------------------------------------------------------------------------------------------ on the humanoid


def short_walk(body_params: dict, seconds: float = 3.0) -> CPGController:
    body = Humanoid(Humanoid.Params(duration=seconds, finish_line=100.0, start_noise=0.02))
    c = controller()
    samples = []

    class Link(InProcessLink):
        def step(self, frame):
            command = super().step(frame)
            samples.append((c.network.time, c.network.slope_estimate, c.network.ankle_centre))
            return command

    body.link = Link(c)
    params = {**ADAPT, "start_ramp": 2.0}
    body.handle(TrialRequest(trial_id=0, seed=1, body_params=body_params, controller_params=params, log=False))
    body.close()
    c.samples = samples
    return c


@pytest.mark.parametrize("slope_deg", [0.0, 10.0])
def test_walking_the_ankle_centres_follow_the_slope_and_stay_in_the_flat_band_on_flat_ground(slope_deg):
    """3 s of the humanoid's gait (start ramp 2 s) from a standing start: on the flat the sensed slope and the ankle
    centres stay within the flat band (0.035 rad, terrain.FLOORS), on a 10-deg ramp they converge to it (the sensed
    slope within 2 deg; measured 11-11.5 deg, a foot pressing flat tilts it about 1 deg)."""
    c = short_walk({"slope_deg": slope_deg})
    spec = c.circuit.ankle_adaptation
    after = [s for s in c.samples if s[0] >= 1.0]
    estimate = np.array([s[1] for s in after])
    centre = np.array([s[2] for s in after])
    slope = math.radians(slope_deg)
    if slope_deg == 0.0:
        assert np.max(np.abs(estimate)) < 0.035 and np.max(np.abs(centre)) < 0.035
    else:
        assert np.max(np.abs(estimate - slope)) < math.radians(2.0)
        assert np.max(np.abs(centre - spec.per_slope_up * slope)) < abs(spec.per_slope_up) * math.radians(2.0)


def test_the_humanoid_weighs_its_total_mass_and_says_when_a_foot_reaches_the_next_ground():
    import pybullet as pb

    body = Humanoid(Humanoid.Params(duration=0.5, total_mass=4.3))
    body.link = InProcessLink(controller())
    result = body.handle(TrialRequest(trial_id=0, seed=0, body_params={"terrain": "0.08:0,2:5"}, controller_params={},
                                      log=False))  # fmt: skip
    masses = [pb.getDynamicsInfo(body.robot, i, physicsClientId=body.client)[0] for i in range(-1, pb.getNumJoints(
        body.robot, physicsClientId=body.client))]  # fmt: skip
    assert sum(masses) == pytest.approx(4.3, rel=1e-9) and body.mass == pytest.approx(4.3)
    assert 0.0 <= result.metrics["terrain_reached"] < 0.1  # the toes stand past x = 0.08 m from the start
    far = body.handle(TrialRequest(trial_id=1, seed=0, body_params={"terrain": "3.0:0,2:5"}, controller_params={},
                                   log=False))  # fmt: skip
    assert far.metrics["terrain_reached"] == -1.0
    flat = body.handle(TrialRequest(trial_id=2, seed=0, body_params={}, controller_params={}, log=False))
    assert "terrain_reached" not in flat.metrics
    body.close()
