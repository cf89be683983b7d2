"""Pattern switching (digest §7.11; issue 23 items 3 and 4): ``theta0: continuous`` is the default and keeps every
position command continuous through a switch, where ``theta0: angle`` (the author's 2017 scripts, digest §5) makes
the reflex-laden joints jump; ``kick_direction: motion`` signs each kick by the way its joint moves (E4.4)."""

from __future__ import annotations

import numpy as np
import pytest

from sfl_brain.modules.controllers.cpg import CPGController, CPGParams, PatternSwitch, switch_text
from sfl_brain.modules.cpg import CPGNetwork, validate_circuit
from sfl_brain.modules.cpg.circuit import Switch, read_circuit_data

from .test_cpg_controller import start, tick

LEGS = [
    "hip_pitch_l",
    "hip_pitch_r",
    "hip_roll_l",
    "hip_roll_r",
    "knee_l",
    "knee_r",
    "ankle_pitch_l",
    "ankle_pitch_r",
    "ankle_roll_l",
    "ankle_roll_r",
]
SWITCH_TICK = 200  # the switch at 2.0 s acts in tick 200


def kinematic_commands(circuit_name: str, switch: dict, ticks: int = 260) -> tuple[np.ndarray, CPGNetwork]:
    """The circuit with one switch, each joint's sensed angle its last command (a servo that follows exactly): the
    commands of every tick, (ticks, joints)."""
    data = read_circuit_data(circuit_name)
    data["switches"] = [switch]
    circuit = validate_circuit(data)
    network = CPGNetwork(circuit)
    sensors = np.zeros(len(circuit.inputs))
    angles = [circuit.inputs.index(j.angle_input) for j in circuit.joints]
    commands = []
    for _ in range(ticks):
        network.advance(sensors)
        commands.append(network.command())
        sensors[angles] = commands[-1]
    return np.array(commands), network


def test_continuous_is_the_default_of_both_switch_schemas():
    assert Switch(joints={"knee_l": {"sigma_s": 1.0, "sigma_f": 0.25}}, at=1.0).theta0 == "continuous"
    assert PatternSwitch().theta0 == "continuous"
    assert PatternSwitch(trigger="time", joints={"knee_l": "plateau"}).circuit_entry()["theta0"] == "continuous"


def test_a_continuous_switch_keeps_every_command_continuous_where_theta0_angle_jumps():
    """The humanoid walking kinematically; at 2.0 s every leg joint switches to quiescence (E4.7's kind of switch).
    With the default each switched command stays at its angle on the switch's tick (no change at all), and no command
    changes more than a tick of walking does; with ``theta0: angle`` the knees jump by their reflexes' offset."""
    joints = {name: {"sigma_s": 1.0, "sigma_f": 0.25} for name in LEGS}
    steps = {}
    for theta0 in ("continuous", "angle"):
        commands, network = kinematic_commands("humanoid_nao", {"joints": joints, "at": 2.0, "theta0": theta0})
        assert [event.time for event in network.switch_events] == [pytest.approx(2.0)]
        change = np.abs(np.diff(commands, axis=0))  # change[k]: from tick k to tick k + 1
        steps[theta0] = change[SWITCH_TICK - 1], change[100 : SWITCH_TICK - 1].max()  # the switch, walking before
        switched = [network.circuit.joint_index(name) for name in LEGS]
        if theta0 == "continuous":
            np.testing.assert_allclose(change[SWITCH_TICK - 1, switched], 0.0, atol=1e-12)
    at_switch, walking = steps["continuous"]
    assert at_switch.max() < 0.01 and at_switch.max() <= walking  # rad: the shoulders, still walking
    at_switch, walking = steps["angle"]
    knee = network.circuit.joint_index("knee_l")
    assert at_switch[knee] > 0.3 > walking  # rad: the reflexes' offset of the knee (0.81 rad measured)


def switched_once(circuit_name: str, switch: dict, angles: dict[str, tuple[float, float]]) -> CPGNetwork:
    """The circuit with one switch at 0.5 s, every input 0 but the named joints' angles: each at its first value until
    the tick before the switch, its second value on the switch's tick (a 10-ms step of motion)."""
    data = read_circuit_data(circuit_name)
    data["switches"] = [{"at": 0.5, **switch}]
    circuit = validate_circuit(data)
    network = CPGNetwork(circuit)
    sensors = np.zeros(len(circuit.inputs))
    for t in range(51):
        for name, (before, now) in angles.items():
            sensors[circuit.inputs.index(name)] = now if t == 50 else before
        network.advance(sensors)
    return network


def test_motion_signs_each_kick_so_the_rg_pushes_its_joint_further_the_way_it_moves():
    """Planar walker (+ = extension, gain > 0): the left hip extends, so its kick is -|1| (into RG-F; +1 into RG-E);
    the right hip flexes, so its kick is +|-2|; the left knee does not move: its kick as given. The kicks show in the
    RGs after the switch's tick (V = q = 0, then one tick of the kick) and in the event."""
    switch = {
        "joints": {name: {"sigma_s": 0.0, "sigma_f": 2.0} for name in ("hip_l", "hip_r", "knee_l")},
        "joint_kicks": {"hip_r": -2.0},
        "kick_direction": "motion",
    }
    network = switched_once(
        "planar_8link", switch, {"hip_l": (0.1, 0.105), "hip_r": (0.1, 0.095), "knee_l": (-0.2,) * 2}
    )
    [event] = network.switch_events
    assert event.kick_direction == "motion"
    assert event.kicks == {"hip_l": -1.0, "hip_r": 2.0, "knee_l": 1.0}
    assert event.extension_rates == {"hip_l": pytest.approx(0.5), "hip_r": pytest.approx(-0.5), "knee_l": 0.0}
    V = {name: network.membrane_potential[network.circuit.joint_index(name)] for name in ("hip_l", "hip_r", "knee_l")}
    assert V["hip_l"][0] > 0 > V["hip_l"][1]  # E pushed up: extension, the way the hip moves
    assert V["hip_r"][1] > 0 > V["hip_r"][0]  # F pushed up: flexion
    assert V["knee_l"][1] > 0 > V["knee_l"][0]
    assert "(kicks signed by each joint's motion)" in switch_text(event)
    fixed = switched_once("planar_8link", {**switch, "kick_direction": "fixed"}, {"hip_l": (0.1, 0.105)})
    [event] = fixed.switch_events
    assert (event.kick_direction, event.kicks, event.extension_rates) == (
        "fixed",
        {"hip_l": 1.0, "hip_r": -2.0, "knee_l": 1.0},
        {},
    )


@pytest.mark.parametrize(("now", "kick"), [(0.91, 1.0), (0.89, -1.0)])
def test_motion_reads_extension_through_the_sign_of_the_gain(now, kick):
    """Humanoid knee: + rotation is flexion, so its gain is < 0; a knee angle rising is flexing (kick +|1| into RG-F),
    one falling is extending (-|1|)."""
    network = switched_once(
        "humanoid_nao",
        {"joints": {"knee_l": {"sigma_s": 1.0, "sigma_f": 0.25}}, "kick_direction": "motion"},
        {"knee_l": (0.9, now)},
    )
    assert network.gain[network.circuit.joint_index("knee_l")] < 0
    [event] = network.switch_events
    assert event.kicks == {"knee_l": kick}
    assert event.extension_rates["knee_l"] == pytest.approx(-kick, rel=1e-6)


def test_motion_needs_the_joints_angle_and_the_controller_passes_it_on():
    data = read_circuit_data("planar_8link")
    del data["joints"][2]["angle_input"]
    data["switches"] = [
        {"joints": {"knee_l": {"sigma_s": 1.0, "sigma_f": 0.25}}, "at": 1.0, "kick_direction": "motion"}
    ]
    with pytest.raises(Exception) as err:
        validate_circuit(data, "c.yaml")
    assert str(err.value) == (
        "c.yaml: switches.0.joints.knee_l: expected a joint with an `angle_input` (kick_direction: motion reads its "
        "rate); 'knee_l' has none"
    )
    switch = {"trigger": "time", "at": 0.2, "joints": {"hip_l": "plateau"}, "kick_direction": "motion"}
    controller = CPGController(CPGParams(switch=switch))
    reads, _ = start(controller)
    sensors = np.zeros(len(reads))
    for t in range(25):
        sensors[reads.index("hip_l")] = -0.01 * t  # flexing at 1 rad/s
        tick(controller, sensors, t)
    [event] = controller.network.switch_events
    assert event.kicks == {"hip_l": 1.0} and event.extension_rates == {"hip_l": pytest.approx(-1.0)}
