"""Starting from the body's pose (issue 23 item 2, slope-aware starts): the circuit key ``start_from_pose`` sets the
named joints' theta_0 at a trial's first tick so that their command equals the measured pose; on a 10-degree ramp the
humanoid's ankles are pitched by the slope (bodies/humanoid.py ``_place``), and without it their first command is the
flat ground's standing pose."""

from __future__ import annotations

import numpy as np
import pytest

from sfl_brain.bodies.humanoid import JOINT_NAMES, Humanoid
from sfl_brain.body import InProcessLink
from sfl_brain.messages import TrialRequest
from sfl_brain.modules.controllers.cpg import CPGController, CPGParams
from sfl_brain.modules.cpg import CPGNetwork, validate_circuit
from sfl_brain.modules.cpg.circuit import read_circuit_data
from sfl_brain.scenario import ScenarioError

ANKLES = ["ankle_pitch_l", "ankle_pitch_r"]


def first_tick_on_a_ramp(
    overrides: dict, slope_deg: float = 10.0, controller_params: dict | None = None, noise: float = 0.0, ticks: int = 1
) -> tuple[np.ndarray, np.ndarray]:
    """The humanoid standing on a ramp with the humanoid_nao CPG: (the first frame's joint angles, the first
    command), both in JOINT_NAMES order (rad)."""
    body = Humanoid(Humanoid.Params(duration=0.01 * ticks, slope_deg=slope_deg, start_noise=noise))
    body.link = InProcessLink(CPGController(CPGParams(circuit="humanoid_nao", circuit_overrides=overrides)))
    frames, commands = [], []
    sense, actuate = body.sense, body.actuate
    body.sense = lambda: frames.append(sense()) or frames[-1]
    body.actuate = lambda command: (commands.append(np.array(command)), actuate(command))
    body.handle(TrialRequest(trial_id=0, seed=0, body_params={}, controller_params=controller_params or {}, log=False))
    body.close()
    return frames[0][: len(JOINT_NAMES)], commands[0]


def test_on_a_ramp_the_first_command_is_the_measured_pose_with_start_from_pose_only():
    pose, command = first_tick_on_a_ramp({"start_from_pose": ANKLES})
    np.testing.assert_allclose(command, pose, atol=0.01)
    ankles = [JOINT_NAMES.index(name) for name in ANKLES]
    np.testing.assert_allclose(command[ankles], pose[ankles], atol=1e-9)
    pose, command = first_tick_on_a_ramp({})
    gap = np.abs(command - pose)
    # about the slope (0.17 rad): 0.217 and 0.199 measured, the ankles' reflexes and contact sensors reading the ramp
    assert np.all((0.15 < gap[ankles]) & (gap[ankles] < 0.25))
    others = [k for k in range(len(JOINT_NAMES)) if k not in ankles]
    assert gap[others].max() < 0.01


def test_theta0_is_set_at_the_first_tick_only_and_each_trial_again():
    data = read_circuit_data("humanoid_nao")
    data["start_from_pose"] = ["knee_l"]
    circuit = validate_circuit(data)
    network, knee = CPGNetwork(circuit), circuit.joint_index("knee_l")
    sensors = np.zeros(len(circuit.inputs))
    for pose in (0.7, 0.2):  # two trials, two poses
        network.reset()
        sensors[circuit.inputs.index("knee_l")] = pose
        network.advance(sensors)
        assert network.command()[knee] == pytest.approx(pose, abs=1e-12)
        theta0 = network.theta0.copy()
        sensors[circuit.inputs.index("knee_l")] = pose + 0.3
        for _ in range(20):
            network.advance(sensors)
        np.testing.assert_array_equal(network.theta0, theta0)
    plain = CPGNetwork(validate_circuit(read_circuit_data("humanoid_nao")))
    plain.advance(sensors)
    assert plain.theta0[0, knee] == circuit.joints[knee].theta0 != theta0[0, knee]  # without the key: the file's


def test_start_from_pose_names_position_joints_with_angles():
    data = read_circuit_data("humanoid_nao")
    data["start_from_pose"] = ["ankle_pitch_l", "ankle_pich_r", "ankle_pitch_l"]
    with pytest.raises(ScenarioError) as err:
        validate_circuit(data, "c.yaml")
    lines = str(err.value).splitlines()
    assert lines[0].startswith("c.yaml: start_from_pose.1: expected one of the joints ['shoulder_pitch_l', ")
    assert lines[0].endswith("; got 'ankle_pich_r' (did you mean `ankle_pitch_r`?)")
    assert lines[1] == "c.yaml: start_from_pose.2: expected a unique name; got 'ankle_pitch_l' twice"
    data = read_circuit_data("planar_8link")
    data["start_from_pose"] = ["hip_l"]
    with pytest.raises(ScenarioError) as err:
        validate_circuit(data, "c.yaml")
    assert (
        str(err.value) == "c.yaml: start_from_pose.0: expected no joints for a voltage command (position circuits only)"
    )


def test_a_ramp_start_shifts_the_ankles_calibrated_pose_by_the_slope_and_keeps_no_start_noise():
    """The shipped humanoid circuit's start_slope: given the slope it starts on (start_slope_deg), the first command is
    the standing pose on that ramp; the start's own noise is not taken into the commands (start_from_pose would keep
    it as an ankle offset for the whole walk)."""
    pose, command = first_tick_on_a_ramp({}, controller_params={"start_slope_deg": 10.0})
    np.testing.assert_allclose(command, pose, atol=0.01)  # every joint, the ankles included
    ankles = [JOINT_NAMES.index(name) for name in ANKLES]
    np.testing.assert_allclose(command[ankles], -0.35 - np.radians(10.0), atol=1e-9)
    noisy_pose, noisy = first_tick_on_a_ramp({}, controller_params={"start_slope_deg": 10.0}, noise=0.05)
    assert np.abs(noisy_pose[ankles] - pose[ankles]).max() > 0.01  # the start differs ...
    np.testing.assert_allclose(noisy[ankles], command[ankles], atol=1e-9)  # ... the ankle commands do not
    with pytest.raises(ValueError, match="start_slope_deg: circuit planar_8link has no start_slope joints to shift"):
        CPGController(CPGParams(circuit="planar_8link")).configure({"start_slope_deg": 5.0}, 0)
