"""The controller side of chapter 5 on the humanoid (issue 21, items 1, 4, 5): the motor-neuron gains in pitch and roll
as trial parameters (w1, w2 of L1631 and Fig. 5.9's caption; circuit key ``gain_groups``), the torso held about 10 deg
from the vertical (L1764, digest §7.18; circuit key ``posture``), and switching parameters while walking when the torso
pitch says the terrain changed (§5.8, L1759-1766; digest §7.17). On the real humanoid (bodies/humanoid.py) with the
controller in the body's process. "The digest" is CPG-HUMANOID.md.

The humanoid's chapter-5 keys are given here as ``circuit_overrides`` (``CH5``); they are the YAML proposed for
modules/cpg/circuits/humanoid_nao.yaml."""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest
import yaml

from sfl_brain.bodies.humanoid import Humanoid
from sfl_brain.body import InProcessLink
from sfl_brain.messages import TrialRequest
from sfl_brain.modules.controllers.cpg import TRIAL_PARAMS, CPGController, CPGParams, terrain_switch_text
from sfl_brain.modules.cpg import CPGNetwork, validate_circuit
from sfl_brain.modules.cpg.circuit import read_circuit_data
from sfl_brain.scenario import ScenarioError
from sfl_brain.telemetry import CaptureTelemetry, Event

from .test_cpg_controller import scenario_problems, start, tick

DT = 0.01  # s, the control tick
PITCH = [  # Fig. 5.7 (L1621): shoulder pitch, hip pitch, knee pitch, ankle pitch, both sides
    "shoulder_pitch_l",
    "shoulder_pitch_r",
    "hip_pitch_l",
    "hip_pitch_r",
    "knee_l",
    "knee_r",
    "ankle_pitch_l",
    "ankle_pitch_r",
]
ROLL = ["hip_roll_l", "hip_roll_r", "ankle_roll_l", "ankle_roll_r"]  # hip roll, ankle roll, both sides
TARGET = math.radians(10.0)  # L1764: "we keep this angle closed to 10 deg with the vertical direction"
POSTURE = {
    "input": "torso_pitch",
    "target": 0.1745,
    "gain": 0.1,
    "joints": {"ankle_pitch_l": 1, "ankle_pitch_r": 1},
    "limit": 0.15,
}
CH5 = {"gain_groups": {"pitch": PITCH, "roll": ROLL}, "posture": POSTURE}
SWITCH_TO = {"next_gain_pitch": 1.2, "next_gain_roll": 0.8, "next_sigma_s": 4.0}  # an uphill neuron, say
RAMP = "1.0:0,3:10"  # flat for 1 m, then 10 deg uphill (§5.7's slope)


def humanoid_controller(overrides: dict | None = None, **params) -> CPGController:
    return CPGController(CPGParams(circuit="humanoid_nao", circuit_overrides=CH5 if overrides is None else overrides,
                                   **params))  # fmt: skip


# ------------------------------------------------------------------------------------------ the circuit keys


def circuit_problems(changes: dict, base: str = "humanoid_nao") -> list[str]:
    data = read_circuit_data(base)
    data.update(changes)
    with pytest.raises(ScenarioError) as err:
        validate_circuit(data, "c.yaml")
    return str(err.value).splitlines()


def test_the_gain_groups_name_joints_each_in_one_group():
    data = read_circuit_data("humanoid_nao")
    data.update(CH5)
    circuit = validate_circuit(data)
    assert circuit.gain_groups == {"pitch": PITCH, "roll": ROLL}
    lines = circuit_problems({"gain_groups": {"pitch": ["hip_pich_l", "knee_l"], "roll": ["knee_l", "hip_roll_l"]}})
    assert lines[0].startswith("c.yaml: gain_groups.pitch.0: expected one of the joints ['shoulder_pitch_l', ")
    assert lines[0].endswith("; got 'hip_pich_l' (did you mean `hip_pitch_l`?)")
    assert lines[1] == (
        "c.yaml: gain_groups.roll.0: expected a joint in at most one gain group; got 'knee_l' already in group 'pitch'"
    )
    [line] = circuit_problems({"gain_groups": {"pitch": ["knee_l", "knee_l"]}})
    assert (
        line
        == "c.yaml: gain_groups.pitch.1: expected a joint in at most one gain group; got 'knee_l' twice in this group"
    )
    [line] = circuit_problems({"gain_groups": {"yaw": ["knee_l"]}})
    assert line.startswith("c.yaml: gain_groups.yaw") and "'pitch' or 'roll'" in line


def test_the_posture_names_an_input_and_joints_with_signs_and_a_limit():
    assert validate_circuit({**read_circuit_data("humanoid_nao"), "posture": POSTURE}).posture.target == 0.1745
    lines = circuit_problems({"posture": {**POSTURE, "input": "torso_pich", "joints": {"ankle_pich_l": 1}}})
    assert lines[0].startswith("c.yaml: posture.input: expected one of the inputs [")
    assert lines[0].endswith("; got 'torso_pich' (did you mean `torso_pitch`?)")
    assert lines[1].startswith("c.yaml: posture.joints.ankle_pich_l: expected one of the joints [")
    lines = circuit_problems({"posture": {**POSTURE, "joints": {"ankle_pitch_l": 2}, "limit": 0.0, "gain": -1.0}})
    assert [line.split(":")[1].strip() for line in lines] == [
        "posture.gain",
        "posture.joints.ankle_pitch_l",
        "posture.limit",
    ]
    planar = {**POSTURE, "input": "pelvis", "joints": {"ankle_l": 1}}
    assert circuit_problems({"posture": planar}, base="planar_8link") == [
        "c.yaml: posture: expected none for a voltage command (position circuits only)"
    ]


# ------------------------------------------------------------------------------------------ MN gains (w1, w2)


def commands(params: dict, kinematic: bool, ticks: int = 1000) -> np.ndarray:
    """The humanoid CPG's commands (ticks, joints) over its last 4 s, fed a standing frame: held fixed, or driven
    kinematically (each joint's angle input = its last command, an ideal servo)."""
    controller = humanoid_controller()
    reads, _ = start(controller, params={"posture_gain": 0.0, **params})  # no drift of the ankles' offsets
    circuit = controller.circuit
    sensors = np.zeros(len(reads))
    angles = [reads.index(j.angle_input) for j in circuit.joints]
    sensors[angles] = [j.theta0 for j in circuit.joints]
    sensors[reads.index("torso_pitch")] = 0.04  # the standing pose's
    for foot in ("heel_l", "toe_l", "heel_r", "toe_r"):
        sensors[reads.index(foot)] = 12.5  # half a foot's share of the weight
    out, command = [], controller.network.command()
    for t in range(ticks):
        if kinematic:
            sensors[angles] = command
        command = tick(controller, sensors, t)
        out.append(command)
    return np.array(out[-400:])


def half_range(x: np.ndarray) -> np.ndarray:
    return (x.max(axis=0) - x.min(axis=0)) / 2


def test_the_gain_multipliers_scale_each_groups_oscillation_and_no_other_joint():
    pitch = np.isin([j.name for j in humanoid_controller().circuit.joints], PITCH)
    roll = ~pitch
    calibrated = commands({}, kinematic=False)
    for params, scale in (
        ({"gain_pitch": 1.5}, np.where(pitch, 1.5, 1.0)),
        ({"gain_roll": 0.5}, np.where(roll, 0.5, 1)),
    ):
        scaled = commands(params, kinematic=False)
        np.testing.assert_allclose(half_range(scaled) / half_range(calibrated), scale, rtol=1e-9)
        np.testing.assert_allclose(scaled.mean(axis=0), calibrated.mean(axis=0), atol=0.01)  # about the rest drive
    # driven kinematically the reflexes (ES/FS, AS) answer the larger swing: every pitch joint swings wider, by less
    # than 1.5 (measured: shoulders 1.48, hips 1.38, knees 1.15, ankles 1.39); the roll joints exactly as before
    calibrated = commands({}, kinematic=True)
    ratio = half_range(commands({"gain_pitch": 1.5}, kinematic=True)) / half_range(calibrated)
    assert np.all((ratio[pitch] > 1.1) & (ratio[pitch] <= 1.5))
    np.testing.assert_allclose(ratio[roll], 1.0, rtol=1e-9)


def test_at_rest_the_command_is_the_calibrated_one_whatever_the_multipliers():
    """The multipliers scale the motor neurons' drive about its value at rest (the reflexes' offset on the first
    frame), so with the RGs at rest (no kicks) every multiplier commands the calibrated standing pose; literally,
    theta_0 + m G (MN_E - MN_F), m = 0 would drop the knees by 0.5 rad."""
    frame = np.zeros(len(humanoid_controller().circuit.inputs))
    rest = None
    for gains in ({}, {"gain_pitch": 0.0, "gain_roll": 0.0}, {"gain_pitch": 1.7, "gain_roll": 0.3}):
        controller = humanoid_controller({**CH5, "kicks": []})
        start(controller, params=gains)
        command = tick(controller, frame, 0)
        rest = command if rest is None else rest
        np.testing.assert_allclose(command, rest, atol=1e-12)


def test_each_trial_starts_from_the_calibrated_gains():
    controller = humanoid_controller()
    network = controller.network
    calibrated, theta0 = network.gain.copy(), network.theta0.copy()
    start(controller, params={"gain_pitch": 1.5, "gain_roll": 0.25})
    tick(controller, np.zeros(len(controller.circuit.inputs)), 0)
    knee, hip_roll = controller.circuit.joint_index("knee_l"), controller.circuit.joint_index("hip_roll_l")
    assert network.gain[knee] == 1.5 * calibrated[knee] and network.gain[hip_roll] == 0.25 * calibrated[hip_roll]
    assert network.gain_multipliers["pitch"][0] == 1.5
    start(controller, params={})
    np.testing.assert_array_equal(network.gain, calibrated)
    np.testing.assert_array_equal(network.theta0, theta0)
    assert {"gain_pitch", "gain_roll", "posture_gain"} <= set(TRIAL_PARAMS)


def test_the_humanoid_walks_stands_or_falls_with_the_multipliers():
    """Probe facts on the flat, 1.5 m (seed 0, no start noise): (1, 1) walks in 13.2 s, (1.2, 1) in 11.4 s, (0.8, 1)
    in 28.7 s; (1.5, 1) falls at 1.3 s; (0, 0) stands for 30 s. Two of them here."""
    standing = walk({"gain_pitch": 0.0, "gain_roll": 0.0, "posture_gain": 0.0}, seconds=5.0, finish_line=1.5)
    assert not standing.result.metrics["fell"] and abs(standing.result.metrics["distance"]) < 0.05
    faster = walk({"gain_pitch": 1.2, "posture_gain": 0.0}, seconds=20.0, finish_line=1.5)
    assert faster.result.success and faster.result.metrics["time"] < 12.5  # the calibrated gait: 13.2 s


# ------------------------------------------------------------------------------------------ on the humanoid


class Walk:
    """One trial of the humanoid with the chapter-5 CPG in its process, and per control tick (``t`` s, the tick's
    start): the torso pitch the controller read (rad), the torso's x (m), the posture shift (rad), the group gain
    multipliers and the hip pitch's sigma_s after the tick."""

    def __init__(self, params: dict, body_params: dict, seconds: float, finish_line: float, overrides=None) -> None:
        body = Humanoid(Humanoid.Params(duration=seconds, finish_line=finish_line))
        self.controller = controller = humanoid_controller(overrides)
        body.link = InProcessLink(controller)
        pitch_at = controller.circuit.inputs.index("torso_pitch")
        hip = 2 * controller.circuit.joint_index("hip_pitch_l")
        rows = []
        step = controller.step

        def recorded(sensors: np.ndarray) -> np.ndarray:
            t, x = controller.network.time, body.torso_position[0]
            command = step(sensors)
            network = controller.network
            shift = network.posture_shift
            gains = network.gain_multipliers
            rows.append(
                (t, sensors[pitch_at], x, shift[0], gains["pitch"][0], gains["roll"][0], network.sigma_s[0, hip])
            )
            return command

        controller.step = recorded
        request = TrialRequest(trial_id=0, seed=0, body_params=body_params, controller_params=params, log=False)
        self.result = body.handle(request)
        body.close()
        self.t, self.pitch, self.x, self.shift, self.gain_pitch, self.gain_roll, self.sigma_s = np.array(rows).T
        self.network = controller.network

    def mean_pitch(self, start: float, end: float = math.inf) -> float:
        return float(self.pitch[(self.t >= start) & (self.t < end)].mean())


@functools.cache
def _walk(params: tuple, body_params: tuple, seconds: float, finish_line: float) -> Walk:
    return Walk(dict(params), dict(body_params), seconds, finish_line)


def walk(params: dict, body_params: dict | None = None, seconds: float = 12.0, finish_line: float = 100.0) -> Walk:
    """A trial of the humanoid shared by the tests (cached by its parameters; the finish line far away by default)."""
    return _walk(tuple(sorted(params.items())), tuple(sorted((body_params or {}).items())), seconds, finish_line)


def test_the_posture_term_brings_the_mean_torso_pitch_toward_10_degrees():
    """Flat walk, 12 s (the finish line moved away): the calibrated gait leans forward 0.085 rad on average; with the
    posture term (gain 0.1 /s, target 0.1745 rad, both ankle pitches + = NAO's extension) the torso comes to about
    10 deg: a torso leaning too little dorsiflexes the ankles (shift < 0), one leaning too far extends them."""
    off = walk({"posture_gain": 0.0})
    on = walk({})
    assert off.result.metrics["distance"] > 1.0 and on.result.metrics["distance"] > 1.0  # both walk
    assert np.all(off.shift == 0.0)
    before, after = off.mean_pitch(6.0), on.mean_pitch(6.0)
    assert before < 0.11  # measured 0.085
    assert abs(after - TARGET) < 0.4 * abs(before - TARGET)  # measured: see the report
    assert -0.06 < on.shift[-1] < 0.0  # the ankles dorsiflexed a little, far from the limit


def test_the_posture_shift_is_bounded_by_its_limit():
    """The wrong sign on a standing robot (RGs at rest): the torso leans back and the shift runs to the limit and
    stays there; theta_0 of the ankles = the file's + the shift."""
    backwards = {"ankle_pitch_l": -1, "ankle_pitch_r": -1}
    wrong = {**CH5, "kicks": [], "posture": {**POSTURE, "gain": 0.5, "joints": backwards, "limit": 0.05}}
    trial = Walk({}, {}, seconds=4.0, finish_line=100.0, overrides=wrong)
    assert np.all(np.abs(trial.shift) <= 0.05 + 1e-15)
    assert trial.shift[-1] == 0.05 and np.argmax(trial.shift == 0.05) < 300  # pinned within 3 s
    network = trial.network
    for name in ("ankle_pitch_l", "ankle_pitch_r"):
        j = network.circuit.joint_index(name)
        assert network.theta0[0, j] == pytest.approx(network.circuit.joints[j].theta0 + 0.05, abs=1e-12)


def test_the_posture_term_is_an_integral_of_the_lean():
    """Driven by hand: each tick the shift moves by gain sign (input - target) dt; posture_gain 0 is off; the next
    trial starts from the file's offsets."""
    controller = humanoid_controller(
        {**CH5, "posture": {**POSTURE, "joints": {"ankle_pitch_l": 1, "ankle_pitch_r": -1}}}
    )
    reads, _ = start(controller, params={"posture_gain": 0.5})
    network, ankle = controller.network, controller.circuit.joint_index("ankle_pitch_r")
    sensors = np.zeros(len(reads))
    sensors[reads.index("torso_pitch")] = (
        POSTURE["target"] + 0.2
    )  # 0.2 rad past the target: 0.5 x 0.2 x 0.01 = 0.001 per tick
    for t in range(10):
        tick(controller, sensors, t)
    np.testing.assert_allclose(network.posture_shift, [0.01, -0.01], rtol=1e-9)
    assert network.theta0[0, ankle] == pytest.approx(controller.circuit.joints[ankle].theta0 - 0.01, abs=1e-12)
    start(controller, params={"posture_gain": 0.0})
    for t in range(10):
        tick(controller, sensors, t)
    np.testing.assert_array_equal(network.posture_shift, [0.0, 0.0])
    assert network.theta0[0, ankle] == controller.circuit.joints[ankle].theta0


# ------------------------------------------------------------------------------------------ terrain switch (§5.8)


def threshold_from_the_flat(trial: Walk) -> float:
    """§7.17: mean - 1.5 x half range of the torso pitch walking the flat (from the start-up's end, 3 s, until the
    torso is 0.2 m before the ramp); below it the torso has leant back more than flat walking ever does."""
    flat = (trial.t >= 3.0) & (np.cumsum(trial.x >= 0.8) == 0)
    pitch = trial.pitch[flat]
    return float(pitch.mean() - 1.5 * (pitch.max() - pitch.min()) / 2)


def ramp_walks() -> tuple[Walk, float]:
    off = walk({"terrain_switch": "off", "switch_threshold": 0.0, "switch_when": "below", **SWITCH_TO},
               {"terrain": RAMP}, seconds=12.0)  # fmt: skip
    return off, threshold_from_the_flat(off)


def switching(mode: str) -> Walk:
    _, threshold = ramp_walks()
    params = {"terrain_switch": mode, "switch_threshold": threshold, "switch_when": "below", **SWITCH_TO}
    return walk(params, {"terrain": RAMP}, seconds=12.0)


def test_off_never_switches_and_the_threshold_comes_from_the_flat_gait():
    off, threshold = ramp_walks()
    assert off.network.terrain_switch_events == []
    assert np.all(off.gain_pitch == 1.0) and np.all(off.sigma_s == 5.0)
    assert -0.05 < threshold < 0.05  # measured 0.009 rad: flat mean 0.139 - 1.5 x 0.086
    # on the ramp the torso leans back past it: the uphill start (measured at 9.18 s, x 0.92 m)
    assert off.pitch[off.t >= 3.0].min() < threshold


@pytest.mark.parametrize("mode", ["at_once", "gradual"])
def test_a_terrain_switch_fires_once_where_the_torso_pitch_first_reaches_the_threshold_after_the_start_up(mode):
    off, threshold = ramp_walks()
    trial = switching(mode)
    [event] = trial.network.terrain_switch_events
    after = off.t >= 3.0 - 1e-9  # terrain_switch_after, the module parameter's default
    first = off.t[after][np.argmax(off.pitch[after] <= threshold)]  # the same trial without a switch, so far
    assert event.time == pytest.approx(first) and event.time > 3.0
    assert (event.when, event.mode, event.input) == ("below", mode, "torso_pitch")
    assert event.value <= threshold and event.value == trial.pitch[np.argmin(np.abs(trial.t - event.time))]
    assert trial.x[np.argmin(np.abs(trial.t - event.time))] > 0.8  # at the ramp
    assert event.old == {"gain_pitch": 1.0, "gain_roll": 1.0, "sigma_s": 5.0}
    assert event.new == {"gain_pitch": 1.2, "gain_roll": 0.8, "sigma_s": 4.0}
    k = int(np.argmin(np.abs(trial.t - event.time)))  # the switch's tick
    np.testing.assert_array_equal(trial.gain_pitch[:k], 1.0)
    np.testing.assert_array_equal(trial.sigma_s[:k], 5.0)
    moved = (trial.gain_pitch - 1.0) / 0.2, (trial.gain_roll - 1.0) / -0.2, (trial.sigma_s - 5.0) / -1.0
    if mode == "at_once":
        seconds = 0.0
        for fraction in moved:
            np.testing.assert_allclose(fraction[k:], 1.0, atol=1e-12)
    else:
        seconds = 0.667  # switch_seconds: one cycle of the flat gait
        for fraction in moved:  # linear from the switch's tick (0) to 0.667 s later (1)
            expected = np.clip((trial.t[k:] - event.time) / seconds, 0.0, 1.0)
            np.testing.assert_allclose(fraction[k:], expected, atol=1e-6)
            assert fraction[k + 33] == pytest.approx(0.33 / 0.667, abs=1e-6)  # mid-way
    assert event.seconds == seconds and event.end_time == pytest.approx(event.time + seconds)
    network = trial.network
    knee, roll = network.circuit.joint_index("knee_l"), network.circuit.joint_index("hip_roll_l")
    assert network.gain[knee] == pytest.approx(1.2 * network.circuit.joints[knee].gain)
    assert network.gain[roll] == pytest.approx(0.8 * network.circuit.joints[roll].gain)


def test_a_logged_trial_shows_its_terrain_switch_as_an_event():
    controller = humanoid_controller(terrain_switch_after=0.5, switch_seconds=0.2)
    controller.telemetry = sink = CaptureTelemetry()
    params = {"terrain_switch": "gradual", "switch_threshold": 0.3, "switch_when": "above", "gain_pitch": 0.9,
              "next_gain_pitch": 1.1}  # fmt: skip
    reads, _ = start(controller, params=params, log=True, trial_id=2, t0=24.0, dt=DT)
    sensors = np.zeros(len(reads))
    for t in range(150):
        sensors[reads.index("torso_pitch")] = 0.5 if t < 20 or t >= 100 else 0.0  # above at the start: too early
        tick(controller, sensors, t, trial_id=2)
    [switch] = controller.network.terrain_switch_events
    assert switch.time == pytest.approx(1.0) and switch.old == {"gain_pitch": 0.9} and switch.new == {"gain_pitch": 1.1}
    assert controller.network.gain_multipliers["pitch"][0] == pytest.approx(1.1)
    assert controller.network.sigma_s[0, 0] == 5.0  # next_sigma_s not given: unchanged
    controller.close()  # the end of the logged trial
    [event] = [e for e in sink.of(Event) if e.path == "events/terrain_switch"]
    assert (event.trial, event.time) == (2, pytest.approx(25.0))
    assert event.text == "terrain switch (gradually over 0.2 s): torso_pitch 0.5 rad above 0.3; gain_pitch 0.9 -> 1.1"
    assert terrain_switch_text(switch) == event.text


# ------------------------------------------------------------------------------------------ checks


def test_trial_values_are_checked_with_and_without_the_module_parameters(tmp_path):
    check = CPGController.check_trial_param
    for name, value in [("gain_pitch", 1.5), ("next_gain_roll", 0.0), ("posture_gain", 0.1), ("terrain_switch", "off"),
                        ("terrain_switch", "gradual"), ("switch_when", "below"), ("switch_threshold", -0.02),
                        ("next_sigma_s", 4.0)]:  # fmt: skip
        check(name, value)
        check(name, value, CPGParams(circuit="humanoid_nao", circuit_overrides=CH5))
    for name, value, message in [
        ("terrain_switch", "gradualy", "terrain_switch: expected one of ['off', 'at_once', 'gradual']; got 'gradualy' "
         "(did you mean 'gradual'?)"),
        ("terrain_switch", True, "terrain_switch: expected one of ['off', 'at_once', 'gradual']; got True"),
        ("switch_when", "bellow", "switch_when: expected one of ['above', 'below', 'outside']; got 'bellow' "
         "(did you mean 'below'?)"),
        ("switch_threshold", float("nan"), "switch_threshold: expected a finite number; got nan"),
        ("gain_pitch", -0.5, "gain_pitch: expected a multiplier of the calibrated gains >= 0 (1: the gait); got -0.5"),
        ("next_gain_roll", "1", "next_gain_roll: expected a finite number; got '1'"),
        ("next_sigma_s", -1.0, "next_sigma_s: expected a number >= 0 (Table 4.1: [0, 5]); got -1.0"),
        ("posture_gain", -0.1, "posture_gain: expected a gain in 1/s >= 0 (0: off); got -0.1"),
    ]:  # fmt: skip
        with pytest.raises(ValueError) as err:
            check(name, value)
        assert str(err.value) == message
    planar = CPGParams()  # no gain groups, no posture, no torso_pitch input
    data = read_circuit_data("humanoid_nao")
    del data["gain_groups"], data["posture"]  # the humanoid circuit without chapter 5's keys
    path = tmp_path / "bare.yaml"
    path.write_text(yaml.safe_dump(data))
    bare = CPGParams(circuit=str(path))
    for name, value, params, message in [
        ("gain_pitch", 1.2, planar, "gain_pitch: expected circuit planar_8link to have the gain group 'pitch' "
         "(circuit key gain_groups); it has []"),
        ("next_gain_roll", 1.2, bare, "next_gain_roll: expected circuit humanoid_nao to have the gain group 'roll' "
         "(circuit key gain_groups); it has []"),
        ("posture_gain", 0.1, bare, "posture_gain: expected circuit humanoid_nao to have a posture (circuit key "
         "posture)"),
        ("terrain_switch", "at_once", planar, "terrain_switch: expected the circuit planar_8link to have the input "
         "'torso_pitch' (module parameter terrain_input) to watch; its inputs are "),
    ]:  # fmt: skip
        with pytest.raises(ValueError) as err:
            check(name, value, params)
        assert str(err.value).startswith(message)
        with pytest.raises(ValueError) as err:  # configure says what check_trial_param says
            start(CPGController(params), params={name: value, "switch_threshold": 0.1, "switch_when": "above",
                                                 "next_sigma_s": 4.0})  # fmt: skip
        assert str(err.value).startswith(message)


def test_a_terrain_switch_needs_its_threshold_direction_and_new_parameters():
    controller = humanoid_controller()
    for params, message in [
        ({"terrain_switch": "at_once", "next_sigma_s": 4.0},
         "terrain_switch 'at_once': expected one of switch_threshold (rad) or switch_band (the threshold measured on "
         "the walk: mean +- switch_band x half range, digest §7.17)"),
        ({"terrain_switch": "at_once", "next_sigma_s": 4.0, "switch_threshold": 0.1, "switch_band": 1.5},
         "terrain_switch 'at_once': expected one of switch_threshold (rad) or switch_band (the threshold measured on "
         "the walk: mean +- switch_band x half range, digest §7.17)"),
        ({"terrain_switch": "at_once", "next_sigma_s": 4.0, "switch_band": 1.5},
         "terrain_switch 'at_once': expected the trial parameter switch_when too; got none"),
        ({"terrain_switch": "gradual", "switch_threshold": 0.1, "switch_when": "above"},
         "terrain_switch 'gradual': expected at least one of next_gain_pitch, next_gain_roll, next_sigma_s, "
         "next_theta_mlr (the new condition's parameters); got none"),
    ]:  # fmt: skip
        with pytest.raises(ValueError) as err:
            start(controller, params=params)
        assert str(err.value) == message
    start(controller, params={"terrain_switch": "off", **SWITCH_TO})  # off: the next values are not used


def test_the_module_parameters_are_checked():
    assert CPGParams().terrain_switch_after == 3.0 and CPGParams().switch_seconds == 0.667
    assert scenario_problems({"circuit": "humanoid_nao", "terrain_input": "torso_pich"}) == [
        "s.yaml: modules.controller.params.terrain_input: expected one of the inputs of circuit humanoid_nao "
        "['shoulder_pitch_l', 'shoulder_pitch_r', 'hip_pitch_l', 'hip_pitch_r', 'hip_roll_l', 'hip_roll_r', 'knee_l', "
        "'knee_r', 'ankle_pitch_l', 'ankle_pitch_r', 'ankle_roll_l', 'ankle_roll_r', 'heel_l', 'toe_l', 'heel_r', "
        "'toe_r', 'torso_pitch', 'back', 'torso_pitch_rate']; got 'torso_pich' (did you mean `torso_pitch`?)"
    ]
    [line] = scenario_problems({"switch_seconds": 0.0})
    assert line.startswith("s.yaml: modules.controller.params.switch_seconds: ")


def test_nothing_is_done_per_tick_when_posture_and_switching_are_off():
    network = CPGNetwork(validate_circuit({**read_circuit_data("humanoid_nao"), **CH5}))
    network.set_posture_gain(0.0)
    assert network.posture_gain == 0.0 and network._terrain is None
    network.arm_terrain_switch("torso_pitch", 0.1, "above", mode="at_once", gains={"pitch": 1.2})
    sensors = np.zeros(len(network.circuit.inputs))
    sensors[network.circuit.inputs.index("torso_pitch")] = 0.2
    network.advance(sensors)
    assert network._terrain is None and len(network.terrain_switch_events) == 1  # done: disarmed
    with pytest.raises(ValueError, match="switch_when: expected one of"):
        network.arm_terrain_switch("torso_pitch", 0.1, "up")
    with pytest.raises(ValueError, match="next_gain_yaw: expected a gain group of circuit humanoid_nao"):
        network.arm_terrain_switch("torso_pitch", 0.1, "above", gains={"yaw": 1.0})


def test_switch_band_measures_the_threshold_on_the_walk_itself_by_the_stated_rule():
    """switch_band 1.5: the torso pitch's mean - 1.5 x half range over switch_measure (2 s) from terrain_switch_after
    (3 s), the flat part of the walk (the ramp starts at x = 1 m, reached after 9 s), as threshold_from_the_flat does
    by hand over its own window; detection starts at 5 s, and the switch fires where the pitch first reaches it."""
    off, _ = ramp_walks()
    params = {"terrain_switch": "at_once", "switch_band": 1.5, "switch_when": "below", **SWITCH_TO}
    trial = walk(params, {"terrain": RAMP}, seconds=12.0)
    [event] = trial.network.terrain_switch_events
    window = (off.t >= 3.0 - 1e-9) & (off.t < 5.0 - 1e-9)
    expected = off.pitch[window].mean() - 1.5 * np.ptp(off.pitch[window]) / 2
    assert event.threshold == pytest.approx(expected, abs=1e-9)
    later = off.t >= 5.0 - 1e-9
    assert event.time == pytest.approx(off.t[later][np.argmax(off.pitch[later] <= event.threshold)])
    assert trial.x[np.argmin(np.abs(trial.t - event.time))] > 0.8  # at the ramp, not on the flat


def test_switch_when_outside_fires_on_leaving_the_measured_band_either_way_and_needs_a_band():
    off, _ = ramp_walks()
    params = {"terrain_switch": "at_once", "switch_band": 1.5, "switch_when": "outside", **SWITCH_TO}
    trial = walk(params, {"terrain": RAMP}, seconds=12.0)
    [event] = trial.network.terrain_switch_events
    window = (off.t >= 3.0 - 1e-9) & (off.t < 5.0 - 1e-9)
    mean, half = off.pitch[window].mean(), 1.5 * np.ptp(off.pitch[window]) / 2
    assert event.threshold == pytest.approx((mean - half, mean + half), abs=1e-9)
    later = off.t >= 5.0 - 1e-9
    outside = (off.pitch[later] <= mean - half) | (off.pitch[later] >= mean + half)
    assert event.time == pytest.approx(off.t[later][np.argmax(outside)])
    with pytest.raises(ValueError, match="switch_when 'outside': expected a band"):
        walk({"terrain_switch": "at_once", "switch_threshold": 0.1, "switch_when": "outside", **SWITCH_TO}, {})


def test_a_terrain_switch_moves_theta_mlr_gradually_to_the_new_conditions():
    """next_theta_mlr: chapter 5's uphill learns with E4.6's climbing setting (theta_MLR -0.3), so the switch onto
    the slope moves theta_MLR of (4.9) too, with the signs of §7.6 (PF-E -theta, PF-F +theta), over switch_seconds;
    driven by hand: the torso pitch 0.2 rad, then below the threshold 0 at 4 s."""
    controller = humanoid_controller()
    params = {"terrain_switch": "gradual", "switch_threshold": 0.0, "switch_when": "below", "next_theta_mlr": -0.3}
    reads, _ = start(controller, params=params)
    network = controller.network
    f_cols = 2 * np.arange(network.n_joints) + 1
    e_cols = 2 * np.arange(network.n_joints)
    sensors = np.zeros(len(reads))
    sensors[reads.index("torso_pitch")] = 0.2
    theta = []
    for t in range(500):
        if t == 400:
            sensors[reads.index("torso_pitch")] = -0.1
        tick(controller, sensors, t)
        theta.append(network.theta_mlr_signed[0, f_cols].copy())
        np.testing.assert_array_equal(network.theta_mlr_signed[0, e_cols], -theta[-1])
    theta = np.array(theta)
    [event] = network.terrain_switch_events
    assert event.old == {"theta_mlr": 0.0} and event.new == {"theta_mlr": -0.3}
    k = int(round(event.time / DT))
    assert 400 <= k <= 401
    np.testing.assert_array_equal(theta[:k], 0.0)  # untouched before the switch
    assert -0.3 < theta[k + 30, 0] < 0.0  # on its way, one cycle long (0.667 s)
    np.testing.assert_allclose(theta[k + 70 :], -0.3, atol=1e-12)  # arrived
