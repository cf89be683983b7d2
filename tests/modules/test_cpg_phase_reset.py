"""Phase resetting as a reset of state (thesis L1270-1282, digest §7.10; issue 23 item 1): at a heel strike a leg's RGs
jump to a stored stance-onset state, once per landing and not during the start-up transient; the pulse mode is
unchanged; the stance-onset state is measured on the unperturbed gait (modules/cpg/calibrate.py)."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from sfl_brain.modules.cpg import CPGNetwork, validate_circuit
from sfl_brain.modules.cpg.calibrate import main, stance_states
from sfl_brain.modules.cpg.circuit import apply_overrides, read_circuit_data
from sfl_brain.scenario import ScenarioError

#: a stance-onset state of the left leg's hip and knee, made up (the test only needs a definite one)
STATE = {"hip_l": {"E": [1.5, -0.5], "F": [-2.0, 0.25]}, "knee_l": {"E": [0.75, 1.0], "F": [-0.5, -1.25]}}
STRIKES = (0.5, 1.5, 1.56, 2.5)  # s: heel_l rises at each (1.56: the heel bouncing 60 ms after landing at 1.5)


#: the planar circuit's phase resets as they were before issue 23: pulses written without the new fields
PULSES = [
    {"sensor": "GB_l", "joint": "hip_l", "amplitude": -1.0, "duration": 0.04, "threshold": 0.5, "enabled": True},
    {"sensor": "GB_r", "joint": "hip_r", "amplitude": -1.0, "duration": 0.04, "threshold": 0.5, "enabled": True},
]


def reset_entry(**fields) -> dict:
    entry = {"sensor": "GB_l", "joint": "hip_l", "mode": "state", "joints": ["hip_l", "knee_l"], "state": STATE}
    return {**entry, "refractory": 0.2, "after": 1.0, **fields}


def planar_with(*resets: dict):
    data = read_circuit_data("planar_8link")
    data["phase_resets"] = list(resets)
    return validate_circuit(data, "c.yaml")


def heel_trace(circuit, seconds: float = 3.0) -> np.ndarray:
    """Every input 0 but heel_l: 200 N (GB_l = 0.9997) for 30 ms from each of STRIKES, 0 N (GB_l = 0.1) otherwise;
    ticks of 10 ms."""
    ticks = int(round(seconds / 0.01))
    sensors = np.zeros((ticks, len(circuit.inputs)))
    heel = circuit.inputs.index("heel_l")
    for t in STRIKES:
        start = int(round(t / 0.01))
        sensors[start : start + 3, heel] = 200.0
    return sensors


def fired_at(network: CPGNetwork, sensors: np.ndarray) -> list[float]:
    for frame in sensors:
        network.advance(frame)
    return [round(e.time, 6) for e in network.phase_reset_events]


@pytest.mark.parametrize("mode", ["state", "pulse"])
def test_a_reset_fires_once_per_landing_and_not_before_after(mode):
    """The bounce at 1.56 s is within the 0.2-s refractory time of the landing at 1.5 s; the landing at 0.5 s is in
    the start-up transient (after = 1 s). Without either rule each rising edge fires."""
    circuit = planar_with(reset_entry(mode=mode))
    network = CPGNetwork(circuit)
    assert fired_at(network, heel_trace(circuit)) == [1.5, 2.5]
    assert {e.mode for e in network.phase_reset_events} == {mode}
    ungated = CPGNetwork(planar_with(reset_entry(mode=mode, refractory=0.0, after=0.0)))
    assert fired_at(ungated, heel_trace(circuit)) == [0.5, 1.5, 1.56, 2.5]


def test_a_state_reset_sets_exactly_the_stated_state_of_its_joints_and_nothing_else():
    """The network with the reset equals, bit for bit, the network without resets whose listed RGs are set by hand to
    the stored state at the start of each tick the reset fires: the reset sets (V, q) of E and F of hip_l and knee_l
    to ``STATE`` and touches nothing else. And it does change the rhythm (against no reset at all)."""
    circuit = planar_with(reset_entry())
    resetting, by_hand, untouched = CPGNetwork(circuit), CPGNetwork(circuit), CPGNetwork(circuit)
    by_hand.set_phase_reset("off")
    untouched.set_phase_reset("off")
    cols = [circuit.neuron_index(f"{joint}.{side}") for joint in STATE for side in "EF"]
    V = [STATE[joint][side][0] for joint in STATE for side in "EF"]
    q = [STATE[joint][side][1] for joint in STATE for side in "EF"]
    fired = 0
    for frame in heel_trace(circuit):
        resetting.advance(frame)
        if len(resetting.phase_reset_events) > fired:
            fired = len(resetting.phase_reset_events)
            by_hand.y[0, 0, cols], by_hand.y[0, 1, cols] = V, q
        by_hand.advance(frame)
        untouched.advance(frame)
        np.testing.assert_array_equal(resetting.y, by_hand.y)
    assert fired == 2
    assert np.abs(resetting.y - untouched.y).max() > 0.5


def test_the_trial_mode_makes_every_reset_a_pulse_a_state_reset_or_none_and_reset_restores_the_files():
    circuit = planar_with(reset_entry(), reset_entry(sensor="GB_r", joint="hip_r", mode="pulse", joints=None, state={}))
    network = CPGNetwork(circuit)
    sensors = heel_trace(circuit)
    sensors[:, circuit.inputs.index("heel_r")] = sensors[:, circuit.inputs.index("heel_l")]
    modes = {}
    for mode in ("circuit", "pulse", "off"):
        network.reset()
        network.set_phase_reset(mode)
        fired_at(network, sensors)
        modes[mode] = [(e.time, e.entry, e.mode) for e in network.phase_reset_events]
    assert modes["circuit"] == [(1.5, 0, "state"), (1.5, 1, "pulse"), (2.5, 0, "state"), (2.5, 1, "pulse")]
    assert modes["pulse"] == [(1.5, 0, "pulse"), (1.5, 1, "pulse"), (2.5, 0, "pulse"), (2.5, 1, "pulse")]
    assert modes["off"] == []
    with pytest.raises(ValueError, match=r"\('state'\); none for phase_resets\.1 \['hip_r'\]$"):
        network.set_phase_reset("state")  # the right leg's entry stores no state
    with pytest.raises(ValueError, match=r"expected one of \['off', 'pulse', 'state', 'circuit'\]; got 'on'"):
        network.set_phase_reset("on")
    network.reset()
    np.testing.assert_array_equal(network.phase_reset_as_state, [True, False])
    np.testing.assert_array_equal(network.phase_reset_enabled, [True, True])


def test_pulse_entries_written_with_the_new_fields_at_their_defaults_are_the_old_ones_bit_for_bit():
    plain = PULSES
    explicit = [{**r, "mode": "pulse", "refractory": 0.0, "after": 0.0} for r in plain]
    rng = np.random.default_rng(5)
    old, new = CPGNetwork(planar_with(*plain)), CPGNetwork(planar_with(*explicit))
    sensors = heel_trace(old.circuit) + rng.uniform(-0.3, 0.3, size=(300, len(old.circuit.inputs)))
    for frame in sensors:
        old.advance(frame)
        new.advance(frame)
    np.testing.assert_array_equal(old.neuron_values(), new.neuron_values())
    assert len(new.phase_reset_events) == 4  # each rising edge, the bounce and the early one included


def test_a_state_entry_names_what_exists_and_stores_a_state_for_each_of_its_joints():
    with pytest.raises(ScenarioError) as err:
        planar_with(
            reset_entry(joints=["hip_l", "kne_l", "knee_l"], state={**STATE, "hip_r": STATE["hip_l"]}, sensor="GBl"),
            reset_entry(state={"hip_l": STATE["hip_l"]}),
        )
    assert str(err.value).splitlines() == [
        "c.yaml: phase_resets.0.sensor: expected one of the sensory neurons ['ES_hip_l', 'FS_hip_l', 'ES_hip_r', "
        "'FS_hip_r', 'ES_knee_l', 'FS_knee_l', 'ES_knee_r', 'FS_knee_r', 'ES_ankle_l', 'FS_ankle_l', 'ES_ankle_r', "
        "'FS_ankle_r', 'ES_trunk', 'FS_trunk', 'GB_l', 'GF_l', 'GB_r', 'GF_r', 'FB', 'FF', 'BS', 'BF']; got 'GBl' "
        "(did you mean `GB_l`?)",
        "c.yaml: phase_resets.0.joints.1: expected one of the joints ['hip_l', 'hip_r', 'knee_l', 'knee_r', 'ankle_l', "
        "'ankle_r', 'trunk']; got 'kne_l' (did you mean `knee_l`?)",
        "c.yaml: phase_resets.0.state.hip_r: expected one of the joints this reset sets ['hip_l', 'kne_l', 'knee_l']; "
        "got 'hip_r' (did you mean `hip_l`?)",
        "c.yaml: phase_resets.1.state.knee_l: expected the stance-onset state {E: [V, q], F: [V, q]} of every joint "
        "in `joints` (mode: state); got none",
    ]
    with pytest.raises(ScenarioError) as err:
        planar_with(reset_entry(state={"hip_l": {"E": [1.0], "F": [0.0, 0.0]}, "knee_l": STATE["knee_l"]}))
    assert str(err.value) == (
        "c.yaml: phase_resets.0.state.hip_l.E: list should have at least 2 items after validation, not 1; got [1.0]"
    )
    with pytest.raises(ScenarioError) as err:
        planar_with(reset_entry(state={**STATE, "hip_l": {"E": [1.0, 0.0], "FF": [0.0, 0.0]}}))
    assert str(err.value).splitlines() == [
        "c.yaml: phase_resets.0.state.hip_l.F: required key is missing",
        "c.yaml: phase_resets.0.state.hip_l.FF: unknown key; expected one of ['E', 'F'] (did you mean `F`?)",
    ]
    with pytest.raises(ScenarioError, match=r"phase_resets\.0\.refractory: input should be greater than or equal"):
        planar_with(reset_entry(refractory=-0.1))


# ------------------------------------------------------------------------------------------------
# The stance-onset state, measured (calibrate.py)
# ------------------------------------------------------------------------------------------------


def test_calibration_finds_a_periodic_gait_and_prints_a_snippet_that_validates(capsys):
    """The shipped 8-link circuit on its walker from the E4.2 crouch: after the 3-s transient every heel strike of a
    leg finds its RGs in nearly the same state (the gait is periodic: a spread of a few % of each variable's swing,
    the 10-ms tick's jitter of the strike on the RG's steep rise), and the printed snippet is a valid phase_resets
    list whose state resets the walker then walks with."""
    assert main(["stance", "planar_8link", "--seconds", "8", "--after", "3"]) == 0
    printed = capsys.readouterr().out
    assert "Re-run whenever the gait changes" in printed
    resets = yaml.safe_load(printed)["phase_resets"]
    circuit = apply_overrides(read_circuit_data("planar_8link"), {"phase_resets": resets})
    assert [(r.sensor, r.mode, r.joints) for r in circuit.phase_resets] == [
        ("GB_l", "state", ["hip_l", "knee_l", "ankle_l"]),
        ("GB_r", "state", ["hip_r", "knee_r", "ankle_r"]),
    ]
    for state in stance_states(seconds=8.0, after=3.0):
        assert len(state.strikes) >= 3 and min(state.strikes) >= 3.0
        assert 1.3 < np.median(np.diff(state.strikes)) < 1.45  # s: one gait cycle between a leg's strikes
        v, q = state.largest_relative_spread()
        assert v < 0.05 and q < 0.05, state.spread
        hip = state.mean[state.leg.joint]
        assert hip["E"][0] > 3.0 > -3.0 > hip["F"][0]  # stance onset: the hip's extensor RG is on
    with pytest.raises(ValueError, match=r"leg GB_l: 1 heel strike\(s\) after 3.0 s in 4.0 s; run longer"):
        stance_states(seconds=4.0, after=3.0)
