"""The humanoid's and the CPG's fast paths compute the same numbers as their plain forms, bit for bit.

``Humanoid.actuate`` (the servo in plain floats, one joint read per physics step), ``_foot_pressure`` (one contact
query for the robot, shared out by link; both feet's frames in one query) and ``sense``, and the network's RK4 with
``np.dot``'s undispatched implementation, were made cheaper without changing a bit of a trial. ``Reference`` below is
the humanoid as it was written before (numpy per step, a contact query per foot), and the reference controller's
network calls ``np.dot`` itself; a trial with a push and a ball (contacts on the feet and on the robot) must give the
same sensor frames, commands and metrics, float for float.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import sfl_brain.modules.cpg.network as network_module
from sfl_brain.bodies.humanoid import (
    BALL_WATCH,
    EFFORT,
    FSR_X,
    FSR_Y,
    HOLD_TORQUE,
    LOWER,
    MAX_BACK,
    MOTOR,
    SENSOR_HIGH,
    SENSOR_LOW,
    SPEED,
    UPPER,
    Humanoid,
    _motor_powers,
    pb,
)
from sfl_brain.body import InProcessLink
from sfl_brain.messages import TrialRequest
from sfl_brain.modules.controllers.cpg import CPGController, CPGParams


class Reference(Humanoid):
    """The humanoid's sensing and acting as first written: numpy on 12-vectors every physics step, the contact points
    of each foot asked for separately."""

    def _read_joints(self) -> None:
        states = pb.getJointStates(self.robot, self.joint_index, physicsClientId=self.client)
        q, dq, _, tau = zip(*states, strict=True)
        self.q, self.dq, self.tau = np.array(q), np.array(dq), np.array(tau)

    def _start_joints(self) -> None:  # a trial starts with no torque in both versions (issue 32)
        self._read_joints()
        self.tau = np.zeros(len(self.tau))

    def _foot_pressure(self) -> list[float]:
        c, robot = self.client, self.robot
        toe_x, heel_x = FSR_X
        inner_y, outer_y = FSR_Y
        fsr = [0.0] * 8
        for k, foot in enumerate(self.foot_index):
            contacts = pb.getContactPoints(bodyA=robot, linkIndexA=foot, physicsClientId=c)
            if not contacts:
                continue
            origin, turn = pb.getLinkState(robot, foot, physicsClientId=c)[4:6]
            r = pb.getMatrixFromQuaternion(turn)
            side = 1.0 if k == 0 else -1.0
            for contact in contacts:
                dx, dy, dz = (contact[5][i] - origin[i] for i in range(3))
                x = r[0] * dx + r[3] * dy + r[6] * dz
                y = side * (r[1] * dx + r[4] * dy + r[7] * dz)
                toe = min(max((x - heel_x) / (toe_x - heel_x), 0.0), 1.0)
                outer = min(max((y - inner_y) / (outer_y - inner_y), 0.0), 1.0)
                force = contact[9]
                fsr[4 * k] += force * toe * (1 - outer)
                fsr[4 * k + 1] += force * toe * outer
                fsr[4 * k + 2] += force * (1 - toe) * (1 - outer)
                fsr[4 * k + 3] += force * (1 - toe) * outer
        return fsr

    def sense(self) -> np.ndarray:
        fsr = self._foot_pressure()
        up = self.torso_turn[2]
        imu = [math.atan2(-up[0], up[2]), math.atan2(up[1], up[2]), self.torso_spin[1], self.torso_spin[0]]
        feet = [fsr[2] + fsr[3], fsr[0] + fsr[1], fsr[6] + fsr[7], fsr[4] + fsr[5]]
        values = np.concatenate([self.q, self.dq, self.tau, feet, fsr, imu, (self.back,)])
        return np.minimum(np.maximum(values, SENSOR_LOW), SENSOR_HIGH)

    def actuate(self, command: np.ndarray) -> None:
        p, c, robot, joints = self.params, self.client, self.robot, self.joint_index
        target = np.minimum(np.maximum(command, LOWER), UPPER)
        h = p.control_dt / p.substeps
        back = 0.0
        for k in range(p.substeps):
            error = target - self.q
            speed = np.minimum(np.maximum(p.servo_rate * error, -SPEED), SPEED)
            torque = np.minimum(p.servo_stiffness * np.abs(error) + HOLD_TORQUE, EFFORT)
            pb.setJointMotorControlArray(
                robot,
                joints,
                pb.VELOCITY_CONTROL,
                targetVelocities=speed.tolist(),
                forces=torque.tolist(),
                physicsClientId=c,
            )
            if self.push_force > 0 and self.push_start <= self.t + k * h < self.push_end:
                self._push(self.t + k * h)
                back += max(float(self.push_vector[0]), 0.0) * h
            if self.ball_mass > 0 and self.t + k * h >= self.ball_time - 1e-9 and not self._ball_thrown:
                self._throw()
            pb.stepSimulation(physicsClientId=c)
            if self._ball_thrown and self.t + k * h < self.ball_time + BALL_WATCH:
                back += self._ball_contacts(self.t + (k + 1) * h, h)
            self._read_joints()
            self.energy += float(MOTOR @ self.tau**2) * h
        self.back = min(back / p.control_dt, MAX_BACK)
        self.ticks += 1
        self.t = self.ticks * p.control_dt
        self._read_torso()
        self._judge()


class Recording(InProcessLink):
    """The link that keeps every frame and command of a trial."""

    def __init__(self, controller) -> None:
        super().__init__(controller)
        self.frames: list[np.ndarray] = []
        self.commands: list[np.ndarray] = []

    def step(self, frame):
        command = super().step(frame)
        self.frames.append(np.array(frame.values))
        self.commands.append(np.array(command.values))
        return command


def run(body_class, monkeypatch, dot, body_params: dict, controller_params: dict, seed: int):
    monkeypatch.setattr(network_module, "_dot", dot)
    body = body_class(Humanoid.Params(duration=2.0, start_noise=0.02))
    link = Recording(CPGController(CPGParams(circuit="humanoid_nao")))
    body.link = link
    try:
        results = [
            body.handle(
                TrialRequest(
                    trial_id=i, seed=seed, body_params=body_params, controller_params=controller_params, log=False
                )
            )
            for i in range(2)  # the second on the restored world
        ]
    finally:
        body.close()
    return results, np.array(link.frames), np.array(link.commands)


@pytest.mark.parametrize(
    ("body_params", "controller_params", "seed"),
    [
        ({"ball_mass": 0.5, "ball_speed": 4.0, "ball_time": 0.8, "ball_height": -0.25}, {"alpha_mlr": 0.9}, 2),
        (
            {"slope_deg": 5.0, "push_force": 30.0, "push_time": 0.5, "push_duration": 0.1},
            {"gain_pitch": 0.8, "gain_roll": 1.5, "sigma_s": 3.5, "posture_gain": 0.1, "start_slope_deg": 5.0},
            11,
        ),
    ],
)
def test_a_trial_is_the_same_bit_for_bit_as_the_plain_code_gives(monkeypatch, body_params, controller_params, seed):
    fast = run(Humanoid, monkeypatch, network_module._dot, body_params, controller_params, seed)
    plain = run(Reference, monkeypatch, np.dot, body_params, controller_params, seed)
    for a, b in zip(fast[0], plain[0], strict=True):
        assert a.metrics == b.metrics and a.success == b.success and a.quality == b.quality
    assert fast[1].shape == plain[1].shape and len(fast[1]) > 150
    assert np.array_equal(fast[1], plain[1])  # every sensor frame
    assert np.array_equal(fast[2], plain[2])  # every command
    if "ball_mass" in body_params:
        assert fast[0][0].metrics["ball_impulse"] > 0  # the ball hit: its contacts were in the robot's points


def test_the_ticks_vectorised_motor_power_is_the_per_step_dot_bit_for_bit():
    """``_motor_powers`` (one sum per tick, issue 31) gives each step's ``MOTOR @ tau**2`` float for float: torques of
    every size and sign, 4 steps a tick as the humanoid takes them, and other counts."""
    rng = np.random.default_rng(31)
    for steps in (4, 4, 4, 1, 7):
        for _ in range(2000):
            torques = rng.normal(0.0, 3.0, size=(steps, len(MOTOR))) * rng.uniform(0.0, 2.0, size=(steps, 1))
            per_step = [float(MOTOR @ tau**2) for tau in torques]
            assert _motor_powers(torques.tolist()) == per_step
