"""The position-servo 8-link walker (``planar_8link_servo``, L1201) and its position circuit: the contract, the servo,
walking at the default pattern, part of the pattern space walking and part falling, pushes at a gait phase.

Real pymunk physics; the CPG controller and the walker in one process (``InProcessLink``), as
docs/calibration/planar_servo_grid.py runs them.
"""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from sfl_brain.bodies.planar_8link import (
    COMMANDS,
    MAX_VOLTAGE,
    SENSORS,
    PlanarWalker8,
    PlanarWalker8Servo,
)
from sfl_brain.body import Controller, InProcessLink
from sfl_brain.conformance import check_module
from sfl_brain.messages import TrialRequest
from sfl_brain.modules.controllers.cpg import CPGController, CPGParams
from sfl_brain.registry import resolve
from sfl_brain.signals import names

from ..conftest import ROOT

LEGS = ["hip_l", "hip_r", "knee_l", "knee_r", "ankle_l", "ankle_r"]
JOINTS = ("trunk", "hip_l", "hip_r", "knee_l", "knee_r", "ankle_l", "ankle_r")
CROUCH = np.array([0.0, -0.15, -0.15, -0.3, -0.3, -0.15, -0.15])


class HoldTargets(Controller):
    """Sends one posture as the position targets, every tick."""

    READS = ()
    WRITES = tuple(f"q_{j}" for j in JOINTS)

    def configure(self, params: dict, seed: int) -> None:
        self.posture = np.asarray(params.get("posture", CROUCH), dtype=float)

    def step(self, sensors: np.ndarray) -> np.ndarray:
        return self.posture


def walk(sigma=(2.0, 2.0), seed=0, phase_reset=True, body_params=None, duration=10.0):
    """One trial of the servo walker under its circuit, the pattern on the legs: (result, body)."""
    controller = CPGController(CPGParams(circuit="planar_8link_servo", phase_reset=phase_reset, pattern_joints=LEGS))
    body = PlanarWalker8Servo(PlanarWalker8Servo.Params(duration=duration, initial_knee=-0.3, start_noise=0.02))
    body.link = InProcessLink(controller)
    pattern = {"sigma_s": sigma[0], "sigma_f": sigma[1]}
    request = TrialRequest(trial_id=0, seed=seed, body_params=body_params or {}, controller_params=pattern, log=False)
    return body.handle(request), body


def test_registered_and_conforming():
    cls, _ = resolve("planar_8link_servo")
    assert cls is PlanarWalker8Servo and issubclass(cls, PlanarWalker8)
    check_module(PlanarWalker8Servo)
    assert PlanarWalker8Servo.SENSORS == SENSORS  # the same walker and sensors
    assert names(PlanarWalker8Servo.COMMANDS) == tuple(f"q_{j}" for j in JOINTS)
    assert names(PlanarWalker8.COMMANDS) == names(COMMANDS)  # the voltage walker keeps its commands


def test_the_circuit_file_matches_the_servo_walker():
    circuit = yaml.safe_load((ROOT / "modules/cpg/circuits/planar_8link_servo.yaml").read_text())
    assert circuit["command"] == "position" and circuit["pf_input"] == "bounded"
    assert set(circuit["inputs"]) <= set(names(SENSORS))
    assert {f"q_{j['name']}" for j in circuit["joints"]} == set(names(PlanarWalker8Servo.COMMANDS))
    assert all(0 < j["pf"]["alpha"] <= 10 for j in circuit["joints"])  # Table 4.1's ]0, 10]


def test_the_servo_drives_the_motor_voltage_from_the_position_error():
    body = PlanarWalker8Servo(PlanarWalker8Servo.Params(initial_knee=-0.3))
    body.start_trial(TrialRequest(trial_id=0, seed=0, body_params={}, controller_params={}, log=False))
    body.actuate(CROUCH)
    p, q, omega = body.params, body._angles.copy(), body._speeds.copy()
    target = CROUCH + 0.05
    expected = np.clip(p.servo_gain * (target - q) - p.servo_damping * omega, -MAX_VOLTAGE, MAX_VOLTAGE)
    assert np.allclose(body.motor_voltage(target), expected)
    assert np.all(np.abs(body.motor_voltage(target + 10.0)) <= MAX_VOLTAGE)  # targets clip to the stops, V to 12 V
    assert np.allclose(
        body.motor_voltage(np.full(7, 5.0)), body.motor_voltage(np.array([0.3, 0.4, 0.4, 0, 0, 0.35, 0.35]))
    )


def test_holding_a_crouch_it_stands_on_its_targets():
    body = PlanarWalker8Servo(PlanarWalker8Servo.Params(duration=5.0, initial_knee=-0.3))
    body.link = InProcessLink(HoldTargets())
    result = body.handle(TrialRequest(trial_id=0, seed=0, body_params={}, controller_params={}, log=False))
    assert not result.metrics["fell"] and result.metrics["time"] == pytest.approx(5.0)
    assert np.abs(body._angles - CROUCH).max() < 0.05  # a soft servo (K_p 30 V/rad): a few degrees of sag
    assert result.metrics["energy"] > 0


@pytest.mark.parametrize("phase_reset", [True, False])
def test_it_walks_at_the_default_pattern_over_seeds(phase_reset):
    for seed in range(4):
        result, body = walk(seed=seed, phase_reset=phase_reset)
        m = result.metrics
        assert result.success and m["steps"] >= 2 and not m["fell"], (seed, m)
        assert m["distance"] > 3.0  # it walks forward, about 0.5 m/s
        strikes = np.array(body.heel_strikes)
        assert 1.2 < np.median(np.diff(strikes[strikes >= 2.0])) < 1.5  # one left heel strike per cycle of ~1.35 s


@pytest.mark.parametrize(
    ("sigma", "outcome"),
    [((2.5, 2.5), "walks"), ((0.0, 0.0), "falls"), ((5.0, 5.0), "falls"), ((0.0, 2.5), "stands")],
)
def test_part_of_the_pattern_space_walks_and_part_falls(sigma, outcome):
    result, _ = walk(sigma=sigma)
    m = result.metrics
    got = "walks" if result.success else "falls" if m["fell"] else "stands"
    assert got == outcome, m


def test_a_push_at_a_gait_phase_on_the_servo_walker():
    result, body = walk(body_params={"push_force": 10.0, "push_time": 4.0, "push_phase": 0.5, "push_steps": 1})
    m = result.metrics
    assert m["pushed"] and not m["push_missed"] and m["push_anchor"] in body.heel_strikes
    assert 1.2 < m["gait_period"] < 1.6
    assert 0 <= m["push_onset"] - (m["push_anchor"] + 0.5 * m["gait_period"]) < 0.01 + 1e-9
    assert m["push_impulse"] == pytest.approx(10.0 * m["push_duration"])
