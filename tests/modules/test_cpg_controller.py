"""The CPG as a controller module (modules/controllers/cpg.py): the module contract, the same commands as the network
driven by hand, wiring by name, circuits and overrides as parameters, phase resetting, pattern switching with its
telemetry event, determinism and the codec. "The digest" is CPG-HUMANOID.md."""

import json

import numpy as np
import pytest
from pydantic import ValidationError

from sfl_brain import messages as m
from sfl_brain.conformance import check_module
from sfl_brain.modules.controllers.cpg import CPGController, CPGParams
from sfl_brain.modules.cpg import CPGNetwork, load_circuit
from sfl_brain.modules.cpg.patterns import OSCILLATOR, PLATEAU, QUIESCENT, classify
from sfl_brain.scenario import ScenarioError, load, problems_from
from sfl_brain.telemetry import CaptureTelemetry, Event, Scalars

DT = 0.01  # s, the control tick


def start(controller: CPGController, sensors=None, commands=None, params=None, seed=0, **reset) -> tuple:
    """A ControllerReset for the controller's own layout (or the given one); returns (reads, writes)."""
    reads, writes = CPGController.signals(controller.params)
    controller.handle(
        m.ControllerReset(
            trial_id=reset.pop("trial_id", 0),
            seed=seed,
            params=params or {},
            sensors=list(sensors or reads),
            commands=list(commands or writes),
            **reset,
        )
    )
    return reads, writes


def tick(controller: CPGController, values: np.ndarray, t: int, trial_id: int = 0) -> np.ndarray:
    return controller.handle(m.SensorFrame(trial_id=trial_id, tick=t, values=np.asarray(values, float))).values


def sensor_trace(inputs, ticks: int, seed: int = 3) -> np.ndarray:
    """Random joint angles (rad) and heel strikes every 0.8 s (N), in the circuit's input order."""
    rng = np.random.default_rng(seed)
    sensors = rng.uniform(-0.4, 0.4, size=(ticks, len(inputs)))
    for heel in ("heel_l", "heel_r"):
        if heel in inputs:
            phase = 0 if heel == "heel_l" else 40
            sensors[:, inputs.index(heel)] = np.where((np.arange(ticks) + phase) % 80 < 40, 150.0, 0.0)
    return sensors


def test_the_controller_passes_the_conformance_check():
    check_module(CPGController)


@pytest.mark.parametrize(
    ("circuit", "prefix", "first_read"), [("planar_8link", "v", "hip_l"), ("humanoid_nao", "q", "shoulder_pitch_l")]
)
def test_signals_are_the_circuits_inputs_and_one_command_per_joint(circuit, prefix, first_read):
    params = CPGParams(circuit=circuit)
    reads, writes = CPGController.signals(params)
    loaded = load_circuit(circuit)
    assert reads == tuple(loaded.inputs) and reads[0] == first_read
    assert writes == tuple(f"{prefix}_{j.name}" for j in loaded.joints)
    controller = CPGController(params)
    assert controller.NEURONS == tuple(controller.network.neuron_names())
    assert len(controller.NEURONS) == 8 * len(loaded.joints) + len(loaded.sensory_neurons)  # V, q, PF, MN per side


@pytest.mark.parametrize("circuit", ["planar_8link", "humanoid_nao"])
def test_commands_equal_the_network_driven_by_hand_bit_for_bit(circuit):
    controller = CPGController(CPGParams(circuit=circuit))
    reads, _ = start(controller)
    network = CPGNetwork(load_circuit(circuit))
    for t, values in enumerate(sensor_trace(reads, 300)):
        sent = tick(controller, values, t)
        network.advance(values, DT, 10)
        np.testing.assert_array_equal(sent, network.command())


def test_a_reordered_body_layout_gives_the_same_commands():
    """Wiring by name: the body lists its sensors in another order, with sensors the circuit does not read, and its
    commands in another order; the controller answers the same commands, put in the body's order."""
    reference, shuffled = CPGController(), CPGController()
    reads, writes = start(reference)
    rng = np.random.default_rng(0)
    body_sensors = [*reads, "pelvis_rate", "slope"]
    rng.shuffle(body_sensors)
    body_commands = list(writes)[::-1]
    start(shuffled, sensors=body_sensors, commands=body_commands)
    to_body = [body_sensors.index(name) for name in reads]
    for t, values in enumerate(sensor_trace(reads, 200)):
        frame = np.zeros(len(body_sensors))
        frame[to_body] = values
        mine = tick(reference, values, t)
        theirs = tick(shuffled, frame, t)
        np.testing.assert_array_equal(theirs, mine[::-1])


def test_circuit_overrides_change_the_network():
    params = CPGParams(
        circuit_overrides={
            "couplings.0.weight": 1.5,  # dotted
            "joints": {"2": {"rg": {"sigma_s": 3.0}}},  # nested, as `--set ...circuit_overrides.joints.2.rg.sigma_s=3`
        }
    )
    network = CPGController(params).network
    circuit = network.circuit
    assert network.coupling[circuit.neuron_index("hip_r.F"), circuit.neuron_index("hip_l.E")] == 1.5
    knee = circuit.joint_index("knee_l")
    assert network.sigma_s[0, 2 * knee] == 3.0 and network.sigma_f[0, 2 * knee] == 2.0  # merged, not replaced
    assert CPGController().network.sigma_s[0, 2 * knee] == 2.0


def scenario_problems(params: dict) -> list[str]:
    """What the scenario checker (``sfl check``) says about these controller parameters."""
    with pytest.raises(ValidationError) as err:
        CPGParams.model_validate_json(json.dumps(params), strict=True)
    return [p.render("s.yaml") for p in problems_from(err.value, CPGParams, ("modules", "controller", "params"))]


def test_a_bad_override_names_its_key_path_in_the_circuit():
    assert scenario_problems({"circuit_overrides": {"joints.0.rgg.sigma_s": 1.0}}) == [
        "s.yaml: modules.controller.params.circuit_overrides.joints.0.rgg: no such key; expected one of "
        "['angle_input', 'gain', 'name', 'pf', 'rg', 'synapses'] (did you mean `rg`?)"
    ]
    [line] = scenario_problems({"circuit_overrides": {"joints": {"0": {"synapses": {"ES_hipl": {"MN_E": -0.4}}}}}})
    assert line.startswith(
        "s.yaml: modules.controller.params.circuit_overrides.joints.0.synapses.ES_hipl: "
        "expected one of the sensory neurons ['ES_hip_l', "
    )
    assert line.endswith("; got 'ES_hipl' (did you mean `ES_hip_l`?)")
    assert scenario_problems({"circuit_overrides": {"joints.0.rg.sigma_s": "2"}}) == [
        "s.yaml: modules.controller.params.circuit_overrides.joints.0.rg.sigma_s: expected a number; got '2' "
        "(did you mean `2`?)"
    ]
    [line] = scenario_problems({"circuit": "planar_8lnk"})
    assert line.startswith("s.yaml: modules.controller.params.circuit: ") and "(did you mean `planar_8link`?)" in line
    [line] = scenario_problems({"switch": {"trigger": "time", "joints": {"kne_l": "quiescent"}}})
    assert line.startswith("s.yaml: modules.controller.params.switch.joints.kne_l: expected one of the joints of ")
    assert line.endswith("got 'kne_l' (did you mean `knee_l`?)")


def test_sfl_check_fails_a_set_override_with_the_circuits_key_path(tmp_path):
    scenario = tmp_path / "cpg.yaml"
    scenario.write_text(
        "name: cpg\nprotocol: {kind: learn, trials: 2}\n"
        "space: [{name: s, target: controller.sigma_s, low: 0.0, high: 5.0}]\n"
        "modules:\n  acc: {impl: acc}\n  vigilance: {impl: vigilance}\n  ofc: {impl: ofc}\n"
        "  controller: {impl: 'sfl_brain.modules.controllers.cpg:CPGController'}\n  body: {impl: analytic}\n"
    )
    with pytest.raises(ScenarioError) as err:
        load(scenario, ["modules.controller.params.circuit_overrides.joints.0.rg.sigma_f=-1"])
    assert str(err.value) == (
        f"{scenario}: modules.controller.params.circuit_overrides.joints.0.rg.sigma_f: "
        "input should be greater than or equal to 0; got -1"
    )


def kinematic_run(controller: CPGController, seconds: float) -> np.ndarray:
    """The controller with no body: each joint's sensed angle is its last position command. Commands per tick."""
    reads, writes = start(controller)
    angle_of = {w: reads.index(w[2:]) for w in writes if w[2:] in reads}
    sensors, out = np.zeros(len(reads)), []
    for t in range(int(round(seconds / DT))):
        command = tick(controller, sensors, t)
        for n, w in enumerate(writes):
            if w in angle_of:
                sensors[angle_of[w]] = command[n]
        out.append(command)
    return np.array(out)


def test_the_humanoid_circuit_runs_with_no_body_and_its_hips_swing_in_anti_phase():
    """Digest §7.3 (checked numerically there): tanh synapses, -1 inside a joint and +1 between the hips (E-LH-P
    excites F-RH-P, F-LH-P excites E-RH-P, L1335, L1623) oscillate stably and lock the hip pitches in anti-phase from
    the one-sided kick; the hip pitch swings a walking-sized amplitude (the author's code, ~0.13 rad, digest §5)."""
    controller = CPGController(CPGParams(circuit="humanoid_nao"))
    commands = kinematic_run(controller, 6.0)
    _, writes = CPGController.signals(controller.params)
    left, right = (commands[-200:, writes.index(f"q_hip_pitch_{side}")] for side in "lr")
    assert np.isfinite(commands).all()
    assert 0.05 < np.ptp(left) < 1.0 and 0.05 < np.ptp(right) < 1.0  # rad
    assert np.corrcoef(left, right)[0, 1] < -0.9


def test_phase_reset_on_a_rising_heel_contact_shifts_the_phase():
    """§7.10: the heel contact GB_l rising through 0.5 starts a +1 (RG-E) / -1 (RG-F) pulse of 40 ms into the left hip
    RG (the sign that starts stance). Late in the hip's flexion it brings the extension forward, and the rhythm keeps
    the new phase; with phase_reset off the heel strike changes nothing."""
    strike = 185  # tick: the left hip RG-E is below rest (flexion) from tick 129 to 197 without a reset
    onsets, V = {}, {}
    early = {"phase_resets": {"0": {"after": 0.0}, "1": {"after": 0.0}}}  # the shipped entries wait 2 s: not here
    for enabled in (True, False):
        controller = CPGController(CPGParams(phase_reset="pulse" if enabled else "off", circuit_overrides=early))
        reads, _ = start(controller)
        sensors, hip_v = np.zeros(len(reads)), []
        for t in range(600):
            sensors[reads.index("heel_l")] = 200.0 if t >= strike else 0.0  # N; GB_l = 0.9997 from the strike
            tick(controller, sensors, t)
            hip_v.append(controller.network.membrane_potential[controller.circuit.joint_index("hip_l")])
        V[enabled] = np.array(hip_v)
        extensor = V[enabled][:, 0]
        onsets[enabled] = np.flatnonzero((extensor[:-1] < 0) & (extensor[1:] >= 0))  # extension starts
    np.testing.assert_array_equal(V[True][:strike], V[False][:strike])
    assert V[True][strike + 3, 0] - V[False][strike + 3, 0] > 0.05  # the extensor RG pushed up ...
    assert V[True][strike + 3, 1] - V[False][strike + 3, 1] < -0.05  # ... the flexor RG down
    assert onsets[True][0] == onsets[False][0] < strike  # the first cycle, before the strike
    advance = onsets[False][1:] - onsets[True][1:]
    assert len(advance) >= 3 and (advance >= 3).all()  # 30 ms or more earlier, cycle after cycle


def test_a_time_triggered_switch_changes_the_chosen_joints_patterns_and_is_an_event():
    """E4.4 (L1311, L1317): on the switch the hips go to plateau and the knees to quiescence, with the hip-knee
    synapses inhibited and the ankle-hip ones kept: the ankles keep oscillating. Classified by patterns.py."""
    switch = {
        "trigger": "time",
        "at": 6.0,
        "joints": {
            "hip_l": "plateau",
            "hip_r": "plateau",
            "knee_l": "quiescent",
            "knee_r": {"sigma_s": 1, "sigma_f": 0.25},
        },
        "inhibit": [["hip_l", "knee_l"], ["hip_r", "knee_r"]],
    }
    controller = CPGController(CPGParams(switch=switch))
    controller.telemetry = sink = CaptureTelemetry()
    reads, _ = start(controller, log=True, trial_id=3, t0=30.0, dt=DT)
    network, V = controller.network, []
    for t in range(1400):
        tick(controller, np.zeros(len(reads)), t, trial_id=3)
        V.append(network.membrane_potential[:, 1])  # the flexor RGs
    V = np.array(V)
    switched_at = 600  # ticks
    for joint, after in (("hip_l", PLATEAU), ("hip_r", PLATEAU), ("knee_l", QUIESCENT), ("knee_r", QUIESCENT)):
        j = network.circuit.joint_index(joint)
        assert classify(V[:switched_at, j], DT, 0.08).kind == OSCILLATOR, joint  # walking before
        assert classify(V[switched_at:, j], DT, 0.2).kind == after, joint  # the kick lasts 0.2 s (§7.11)
    ankle = network.circuit.joint_index("ankle_l")
    assert classify(V[switched_at:, ankle], DT, 0.2).kind == OSCILLATOR
    controller.close()  # the end of the logged trial
    [event] = sink.of(Event)
    assert (event.path, event.trial, event.time) == ("events/pattern_switch", 3, pytest.approx(36.0))
    assert event.text.startswith("pattern switch: hip_l -> plateau (sigma_s 0, sigma_f 2), kick +1; ")
    assert event.text.endswith("; couplings silenced between hip_l-knee_l, hip_r-knee_r")
    neurons = {s.path for s in sink.of(Scalars)}
    assert {"neurons/hip_l/E/RG_V", "neurons/hip_l/F/RG_q", "neurons/knee_r/E/PF", "neurons/trunk/F/MN"} <= neurons


def test_a_push_detector_switch_fires_on_the_forward_pitch_rate():
    switch = {"trigger": "push", "push_input": "pelvis", "push_rate": 1.0, "joints": {"knee_l": "quiescent"}}
    controller = CPGController(CPGParams(switch=switch))
    reads, _ = start(controller)
    pelvis = np.zeros(200)
    pelvis[100:] = 0.005 * np.arange(100)  # 0.5 rad/s: no push
    pelvis[150:] = pelvis[150] + 0.02 * np.arange(50)  # 2 rad/s: a push
    for t in range(200):
        sensors = np.zeros(len(reads))
        sensors[reads.index("pelvis")] = pelvis[t]
        tick(controller, sensors, t)
    [event] = controller.network.switch_events
    assert event.time == pytest.approx(1.51)  # the first tick whose change since the last exceeds 1 rad/s x 10 ms


def test_trial_parameters_set_the_pattern_and_descending_control_of_the_chosen_joints():
    controller = CPGController(CPGParams(pattern_joints=["hip_l", "hip_r"]))
    start(controller, params={"sigma_s": 4.0, "alpha_mlr": 0.5})
    network, circuit = controller.network, controller.circuit
    for joint, sigma_s, alpha_mlr in (("hip_l", 4.0, 0.5), ("hip_r", 4.0, 0.5), ("knee_l", 2.0, 1.0)):
        j = circuit.joint_index(joint)
        np.testing.assert_array_equal(network.sigma_s[0, 2 * j : 2 * j + 2], sigma_s)
        np.testing.assert_array_equal(network.sigma_f[0, 2 * j : 2 * j + 2], 2.0)  # not given: the circuit's
        np.testing.assert_array_equal(network.alpha_mlr[0, 2 * j : 2 * j + 2], alpha_mlr)
    start(controller)  # the next trial starts from the circuit again
    assert network.sigma_s[0, 0] == 2.0
    everywhere = CPGController()
    start(everywhere, params={"sigma_s": 1.5, "sigma_f": 3.0})  # E4.2: all joints (L1286)
    np.testing.assert_array_equal(everywhere.network.sigma_s, 1.5)
    with pytest.raises(ValueError, match=r"got \['sigma'\] \(did you mean `sigma_s`\?\)"):
        start(everywhere, params={"sigma": 1.0})
    with pytest.raises(ValueError, match="sigma_f: expected a number >= 0"):
        CPGController.check_trial_param("sigma_f", -1.0)


def test_same_seed_same_commands_and_a_new_trial_starts_afresh():
    def trial(controller: CPGController, trial_id: int) -> np.ndarray:
        reads, _ = start(controller, trial_id=trial_id, seed=5)
        return np.array([tick(controller, s, t, trial_id) for t, s in enumerate(sensor_trace(reads, 150))])

    one, two = CPGController(), CPGController()
    first = trial(one, 0)
    np.testing.assert_array_equal(first, trial(one, 1))
    np.testing.assert_array_equal(first, trial(two, 0))


def test_messages_survive_the_codec():
    """Frames and commands through encode/decode: a controller fed decoded frames sends the same commands, and its
    decoded commands are the commands it sent."""
    direct, decoded = CPGController(), CPGController()
    reads, writes = start(direct)
    reset = m.ControllerReset(
        trial_id=0, seed=0, params={"sigma_s": 2.5}, sensors=list(reads), commands=list(writes), log=False
    )
    direct.handle(reset)
    decoded.handle(m.decode(m.encode(reset)), checked=True)
    for t, values in enumerate(sensor_trace(reads, 50)):
        frame = m.SensorFrame(trial_id=0, tick=t, values=values)
        sent = direct.handle(frame)
        received = m.decode(m.encode(decoded.handle(m.decode(m.encode(frame)), checked=True)))
        assert (received.trial_id, received.tick) == (0, t)
        np.testing.assert_array_equal(received.values, sent.values)
    params = CPGParams(circuit="humanoid_nao", switch={"trigger": "time", "joints": {"knee_l": "plateau"}})
    assert CPGParams.model_validate_json(json.dumps(params.model_dump(mode="json")), strict=True) == params
