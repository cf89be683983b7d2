"""Phase resetting and pattern switching chosen trial by trial (issue 23 item 6): the controller's trial parameters
``phase_reset`` ("off", "pulse", "state", "circuit") and ``switch`` ("none" or a preset of the module parameter
``switches``), their checks, and the module parameters' defaults."""

from __future__ import annotations

import numpy as np
import pytest

from sfl_brain.modules.controllers.cpg import TRIAL_PARAMS, CPGController, CPGParams
from sfl_brain.modules.cpg.circuit import read_circuit_data

from .test_cpg_controller import scenario_problems, start, tick

STATE = {side: [0.5, -0.25] for side in "EF"}
RESETS = [  # the left leg resets its state at heel strike, the right leg's entry is a pulse with no state
    {
        "sensor": "GB_l",
        "joint": "hip_l",
        "mode": "state",
        "joints": ["hip_l", "knee_l"],
        "state": {"hip_l": STATE, "knee_l": STATE},
        "refractory": 0.3,
    },
    {"sensor": "GB_r", "joint": "hip_r"},
]
PRESETS = {
    "hips": {"trigger": "time", "at": 0.5, "joints": {"hip_l": "plateau", "hip_r": "plateau"}},
    "knees": {"trigger": "time", "at": 0.3, "joints": {"knee_l": "quiescent"}},
}


def run(controller: CPGController, params: dict, ticks: int = 150, trial_id: int = 0) -> tuple[list, list]:
    """One trial with heel strikes of both feet every 0.8 s: (phase resets as (time, entry, mode), switches as (time,
    name, joints))."""
    reads, _ = start(controller, params=params, trial_id=trial_id)
    sensors = np.zeros(len(reads))
    for t in range(ticks):
        sensors[reads.index("heel_l")] = sensors[reads.index("heel_r")] = 200.0 if t % 80 >= 40 else 0.0
        tick(controller, sensors, t, trial_id)
    network = controller.network
    resets = [(round(e.time, 6), e.entry, e.mode) for e in network.phase_reset_events]
    switches = [(round(e.time, 6), e.name, sorted(e.patterns)) for e in network.switch_events]
    return resets, switches


def test_a_trial_chooses_how_the_phase_resets_act_and_the_next_trial_starts_from_the_default():
    controller = CPGController(CPGParams(circuit_overrides={"phase_resets": RESETS}))
    assert "phase_reset" in TRIAL_PARAMS and "switch" in TRIAL_PARAMS
    circuit = [(0.4, 0, "state"), (0.4, 1, "pulse"), (1.2, 0, "state"), (1.2, 1, "pulse")]
    assert run(controller, {})[0] == circuit  # the module's default: "circuit"
    assert run(controller, {"phase_reset": "pulse"})[0] == [(t, n, "pulse") for t, n, _ in circuit]
    assert run(controller, {"phase_reset": "off"})[0] == []
    assert run(controller, {"phase_reset": "circuit"})[0] == circuit
    assert run(controller, {})[0] == circuit
    with pytest.raises(ValueError) as err:
        run(controller, {"phase_reset": "state"})
    assert str(err.value) == (
        "phase_reset: expected a stance-onset state for every joint of every phase reset of circuit planar_8link "
        "('state'); none for phase_resets.1 ['hip_r']"
    )
    states_everywhere = [RESETS[0], {**RESETS[0], "sensor": "GB_r", "joint": "hip_r", "joints": None, "state": {}}]
    states_everywhere[1]["state"] = {"hip_r": STATE}
    both = CPGController(CPGParams(circuit_overrides={"phase_resets": states_everywhere}, phase_reset="off"))
    assert run(both, {})[0] == []  # the module's default: off
    assert {mode for _, _, mode in run(both, {"phase_reset": "state"})[0]} == {"state"}


def test_the_module_parameter_takes_true_false_and_the_modes():
    assert CPGParams(phase_reset=True).phase_reset == "circuit"
    assert CPGParams(phase_reset=False).phase_reset == "off"
    assert CPGParams().phase_reset == "circuit"
    assert CPGParams(phase_reset="pulse").phase_reset == "pulse"
    assert scenario_problems({"phase_reset": "stat"}) == [
        "s.yaml: modules.controller.params.phase_reset: expected one of 'off', 'pulse', 'state' or 'circuit'; "
        "got 'stat' (did you mean `state`?)"
    ]
    assert CPGParams(phase_reset="state").phase_reset == "state"  # the shipped circuit stores its stance states
    pulses = [{"sensor": f"GB_{side}", "joint": f"hip_{side}"} for side in "lr"]  # resets with no state
    assert scenario_problems({"phase_reset": "state", "circuit_overrides": {"phase_resets": pulses}}) == [
        "s.yaml: modules.controller.params.phase_reset: expected a stance-onset state for every joint of every phase "
        "reset of circuit planar_8link ('state'); none for phase_resets.0 ['hip_l'], phase_resets.1 ['hip_r']"
    ]


def test_a_trial_arms_one_preset_or_none_and_the_default_is_the_switch_parameter():
    """Every preset is in the network's circuit, none armed unless a trial names it; a trial that says nothing gets the
    module's ``switch``; "none" switches nothing; each trial starts afresh."""
    default = {"trigger": "time", "at": 0.2, "joints": {"knee_r": "quiescent"}}
    controller = CPGController(CPGParams(switch=default, switches=PRESETS))
    assert [(s.name, s.armed) for s in controller.circuit.switches] == [(None, True), ("hips", False), ("knees", False)]
    assert run(controller, {})[1] == [(0.2, None, ["knee_r"])]
    assert run(controller, {"switch": "hips"})[1] == [(0.5, "hips", ["hip_l", "hip_r"])]
    assert run(controller, {"switch": "knees"})[1] == [(0.3, "knees", ["knee_l"])]
    assert run(controller, {"switch": "none"})[1] == []
    assert run(controller, {})[1] == [(0.2, None, ["knee_r"])]
    network, knee = controller.network, controller.circuit.joint_index("knee_r")
    start(controller, params={"switch": "hips"})
    assert network.sigma_s[0, 2 * knee] == 2.0  # reset restored the pattern the last trial's default switch changed
    alone = CPGController(CPGParams(switches=PRESETS))
    assert run(alone, {})[1] == []  # no `switch`: no preset fires unless named


def test_trial_values_are_checked_with_and_without_the_module_parameters():
    check = CPGController.check_trial_param
    check("phase_reset", "pulse")
    check("switch", "anything")  # without params: a preset name cannot be checked
    check("switch", "none", CPGParams())
    check("switch", "hips", CPGParams(switches=PRESETS))
    for name, value, message in [
        ("phase_reset", "puls", "phase_reset: expected one of ['off', 'pulse', 'state', 'circuit']; got 'puls' "
         "(did you mean 'pulse'?)"),
        ("phase_reset", True, "phase_reset: expected one of ['off', 'pulse', 'state', 'circuit']; got True"),
        ("switch", 1.0, 'switch: expected "none" or the name of a preset (a string); got 1.0'),
        ("sigma_s", "2", "sigma_s: expected a finite number; got '2'"),
    ]:  # fmt: skip
        with pytest.raises(ValueError) as err:
            check(name, value)
        assert str(err.value) == message
    params = CPGParams(switches=PRESETS)
    message = "switch: expected \"none\" or one of the presets ['hips', 'knees']; got 'hip' (did you mean 'hips'?)"
    with pytest.raises(ValueError) as err:
        check("switch", "hip", params)
    assert str(err.value) == message
    with pytest.raises(ValueError) as err:  # configure says what check_trial_param says
        start(CPGController(params), params={"switch": "hip"})
    assert str(err.value) == message
    check("phase_reset", "state", params)  # the shipped circuit stores its stance states
    no_states = {"phase_resets": [{"sensor": f"GB_{side}", "joint": f"hip_{side}"} for side in "lr"]}
    with pytest.raises(ValueError) as err:
        check("phase_reset", "state", CPGParams(switches=PRESETS, circuit_overrides=no_states))
    assert str(err.value).startswith("phase_reset: expected a stance-onset state for every joint")


def test_presets_are_validated_like_the_switch():
    problems = scenario_problems(
        {
            "switches": {
                "hips": {"trigger": "time", "joints": {"hipl": "plateau"}, "inhibit": [["hip_l", "kne_l"]]},
                "none": {"trigger": "time", "joints": {"hip_l": "plateau"}},
                "idle": {"joints": {"hip_l": "plateau"}},
            }
        }
    )
    prefix = "s.yaml: modules.controller.params.switches"
    joints = "['hip_l', 'hip_r', 'knee_l', 'knee_r', 'ankle_l', 'ankle_r', 'trunk']"
    assert problems == [
        f"{prefix}.hips.joints.hipl: expected one of the joints of circuit planar_8link {joints}; got 'hipl' "
        "(did you mean `hip_l`?)",
        f"{prefix}.hips.inhibit.0.1: expected one of the joints of circuit planar_8link {joints}; got 'kne_l' "
        "(did you mean `knee_l`?)",
        f"{prefix}.none: expected a preset name (a letter, then letters, digits, _; not 'none'); got 'none'",
        f"{prefix}.idle.trigger: expected 'time' or 'push' (a preset fires on one); got 'none'",
    ]


def test_the_circuit_files_own_switches_stay_armed_unless_a_trial_says_none():
    data_switch = {"joints": {"knee_l": {"sigma_s": 1.0, "sigma_f": 0.25}}, "at": 0.1}
    assert read_circuit_data("planar_8link")["switches"] == []
    controller = CPGController(CPGParams(circuit_overrides={"switches": [data_switch]}, switches=PRESETS))
    assert run(controller, {})[1] == [(0.1, None, ["knee_l"])]
    assert run(controller, {"switch": "hips"})[1] == [(0.5, "hips", ["hip_l", "hip_r"])]  # the chosen preset only
    assert run(controller, {"switch": "none"})[1] == []


def test_a_trial_moves_the_armed_switch_to_its_own_time_and_the_next_trial_starts_from_the_preset():
    controller = CPGController(CPGParams(switches=PRESETS))
    assert "switch_at" in TRIAL_PARAMS
    assert run(controller, {"switch": "hips", "switch_at": 1.0})[1] == [(1.0, "hips", ["hip_l", "hip_r"])]
    assert run(controller, {"switch": "hips"})[1] == [(0.5, "hips", ["hip_l", "hip_r"])]
    assert run(controller, {"switch": "none", "switch_at": 1.0})[1] == []
    for bad in (-1.0, "soon", True, float("nan")):
        with pytest.raises(ValueError, match="switch_at: expected a time in s >= 0"):
            CPGController.check_trial_param("switch_at", bad)
