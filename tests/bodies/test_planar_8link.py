"""The 8-link planar walker of thesis Fig. 4.7 (issue 15): contract, physics, balance, pushes, telemetry.

No boom holds it up: the stand-in controllers here (a joint PD holding a posture, and a SIMBICON-like
gait, Yin et al. 2007) show what the body does with simple feedback; the CPG is tested elsewhere.
"""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from sfl_brain.bodies.planar_8link import (
    MASS,
    PELVIS,
    SENSORS,
    SHANK,
    THIGH,
    TRUNK,
    PlanarWalker8,
)
from sfl_brain.body import Controller, InProcessLink
from sfl_brain.conformance import check_module
from sfl_brain.messages import TrialRequest
from sfl_brain.signals import names
from sfl_brain.telemetry import Arrows2D, CaptureTelemetry, Event, Scalars, Strips2D

from ..conftest import ROOT

JOINTS = ("trunk", "hip_l", "hip_r", "knee_l", "knee_r", "ankle_l", "ankle_r")
VOLTS = tuple(f"v_{j}" for j in JOINTS)
SENSOR_NAMES = names(SENSORS)
CROUCH = np.array([0.0, -0.15, -0.15, -0.3, -0.3, -0.15, -0.15])  # knees bent 0.3 rad, pelvis over the ankles
K_MOTOR = 6.0  # N m per volt, the body's default k_t / R


class HoldPosture(Controller):
    """A joint PD stand-in: V = kp (posture - angle); the motors' back-EMF is the damping."""

    READS = JOINTS
    WRITES = VOLTS
    kp = 100.0  # V / rad: 600 N m / rad at a joint, above m g h = 22 x 9.81 x 0.77 = 166 N m / rad at the ankles

    def configure(self, params: dict, seed: int) -> None:
        self.posture = np.asarray(params.get("posture", CROUCH), dtype=float)

    def step(self, sensors: np.ndarray) -> np.ndarray:
        return np.clip(self.kp * (self.posture - sensors), -12.0, 12.0)


class ExtendLeftKnee(HoldPosture):
    def step(self, sensors: np.ndarray) -> np.ndarray:
        return super().step(sensors) + np.where(np.array(JOINTS) == "knee_l", 6.0, 0.0)


class ZeroVolts(Controller):
    READS = ()
    WRITES = VOLTS

    def configure(self, params: dict, seed: int) -> None:
        pass

    def step(self, sensors: np.ndarray) -> np.ndarray:
        return np.zeros(len(VOLTS))


class SimpleGait(Controller):
    """SIMBICON-like stand-in (Yin, Loken & van de Panne 2007): per leg a lift state (0.3 s) and a
    strike state (until the swing foot lands); PD targets; the stance hip holds the pelvis at a
    forward lean; the swing thigh is placed by centre-of-mass feedback (its offset d from the stance
    ankle and its speed, from the joint angles and the pelvis angle, as an IMU would give)."""

    READS = SENSOR_NAMES  # all of them, to check their bounds while walking
    WRITES = VOLTS
    FORCES = [SENSOR_NAMES.index(n) for n in ("heel_l", "toe_l", "heel_r", "toe_r")]
    PELVIS, PELVIS_RATE = SENSOR_NAMES.index("pelvis"), SENSOR_NAMES.index("pelvis_rate")
    KP = np.array([60.0, 200, 200, 100, 100, 60, 60])  # N m / rad

    def configure(self, params: dict, seed: int) -> None:
        self.stance, self.lifting, self.since, self.d, self.v = 0, True, 0.0, None, 0.0
        self.low = np.full(len(SENSORS), np.inf)
        self.high = -self.low

    def com_from_stance(self, q: np.ndarray, pelvis: float) -> float:
        """Horizontal centre of mass minus the stance ankle, m (forward kinematics from the hip)."""
        ccw = -pelvis  # link angles counter-clockwise (as pymunk's); the pelvis sensor is + forward

        def axis(angle):  # a link's unit vector toward its top
            return np.array([-np.sin(angle), np.cos(angle)])

        pelvis_top = axis(ccw) * PELVIS
        points = [axis(ccw) * PELVIS / 2, pelvis_top + axis(ccw + q[0]) * TRUNK / 2]
        mass = [4.0, 9.0]
        ankles = []
        for hip, knee in ((q[1], q[3]), (q[2], q[4])):
            thigh = ccw - hip
            shank = thigh + knee
            knee_at = -axis(thigh) * THIGH
            ankle_at = knee_at - axis(shank) * SHANK
            points += [knee_at / 2, (knee_at + ankle_at) / 2, ankle_at + (0.05, 0.0)]
            mass += [2.5, 1.5, 0.5]
            ankles.append(ankle_at[0])
        return float(np.average(np.array(points)[:, 0], weights=mass)) - ankles[self.stance]

    def step(self, s: np.ndarray) -> np.ndarray:
        q, forces, pelvis, pelvis_rate = s[:7], s[self.FORCES], s[self.PELVIS], s[self.PELVIS_RATE]
        self.low, self.high = np.minimum(self.low, s), np.maximum(self.high, s)
        self.since += 0.01
        swing = 1 - self.stance
        if self.lifting and self.since >= 0.3:
            self.lifting = False
        elif not self.lifting and self.since > 0.35 and forces[2 * swing] + forces[2 * swing + 1] > 30.0:
            self.stance, self.lifting, self.since, self.d = swing, True, 0.0, None  # the swing foot landed
            swing = 1 - self.stance
        d = self.com_from_stance(q, pelvis)
        if self.d is not None:
            self.v = 0.7 * self.v + 0.3 * (d - self.d) / 0.01
        self.d = d
        thigh, knee, ankle = (0.5, -1.1, -0.2) if self.lifting else (0.2, -0.05, 0.0)
        target = np.zeros(7)
        target[1 + swing] = -pelvis - (thigh + 0.5 * d + 0.2 * self.v)  # swing thigh angle, forward +
        target[3 + swing], target[5 + swing] = knee, ankle
        target[3 + self.stance] = -0.05
        tau = self.KP * (target - q)
        tau[1 + self.stance] = 200.0 * (pelvis - 0.1) + 10.0 * pelvis_rate - tau[1 + swing]  # pelvis 0.1 rad forward
        return np.clip(tau / K_MOTOR, -12.0, 12.0)


def trial(controller=None, duration=10.0, body_params=None, controller_params=None, log=False, **params):
    body = PlanarWalker8(PlanarWalker8.Params(duration=duration, **params))
    body.link = InProcessLink(controller or HoldPosture())
    result = body.handle(
        TrialRequest(
            trial_id=0,
            seed=0,
            body_params=body_params or {},
            controller_params=controller_params or {},
            log=log,
        )
    )
    return body, result


def test_conformance():
    check_module(PlanarWalker8)


def test_fig_4_7_masses_and_links():
    body, _ = trial(duration=0.01)
    assert len(body.space.bodies) == 8
    assert sum(b.mass for b in body.space.bodies) == pytest.approx(22.0) == MASS  # L1192
    kinds = [type(c).__name__ for c in body.space.constraints]
    assert kinds.count("PivotJoint") == kinds.count("RotaryLimitJoint") == kinds.count("DampedRotarySpring") == 7


def test_the_circuit_file_finds_every_input_and_command():
    circuit = yaml.safe_load((ROOT / "modules/cpg/circuits/planar_8link.yaml").read_text())
    assert set(circuit["inputs"]) <= set(names(SENSORS))
    assert {f"v_{j['name']}" for j in circuit["joints"]} == set(names(PlanarWalker8.COMMANDS))


def test_angles_are_zero_standing_and_positive_extending():
    body, _ = trial(duration=0.01, initial_step=0.3)
    angles = dict(zip(SENSOR_NAMES, body.sense().tolist(), strict=True))
    assert angles["hip_l"] < -0.1 < 0.1 < angles["hip_r"]  # left thigh forward (flexed), right behind
    assert angles["ankle_l"] > 0.1 > -0.1 > angles["ankle_r"]  # front shin leans back over a flat foot
    assert abs(angles["trunk"]) < 0.01 and abs(angles["pelvis"]) < 0.01  # after one tick of the PD
    # +6 V on the left knee on top of the PD: it extends (its angle rises toward 0)
    held, _ = trial(duration=0.3, initial_knee=-0.3)
    pushed, _ = trial(ExtendLeftKnee(), duration=0.3, initial_knee=-0.3)
    assert pushed.sense()[3] > held.sense()[3] + 0.02


def test_same_request_same_metrics():
    request = {"push_force": 45.0, "push_time": 0.5, "push_duration": 0.2}
    _, a = trial(duration=2.0, initial_knee=-0.3, body_params=request)
    _, b = trial(duration=2.0, initial_knee=-0.3, body_params=request)
    assert a.metrics == b.metrics and a.metrics["pushed"]


def test_a_pd_stand_in_holds_a_crouch_for_10_s_and_zero_volts_falls():
    body, held = trial(duration=10.0, initial_knee=-0.3)
    assert not held.metrics["fell"] and held.metrics["time"] == pytest.approx(10.0)
    assert not held.success  # standing is no walking: no steps (E4.2, L1243)
    assert np.abs(body.sense()[:7] - CROUCH).max() < 0.02
    _, limp = trial(ZeroVolts(), duration=10.0, initial_knee=-0.3)
    assert limp.metrics["fell"] and limp.metrics["fell_at"] < 3.0


def test_standing_contact_forces_carry_the_body_weight():
    body, _ = trial(duration=2.0, initial_knee=-0.3)
    s = dict(zip(SENSOR_NAMES, body.sense().tolist(), strict=True))
    feet = [s["heel_l"], s["toe_l"], s["heel_r"], s["toe_r"]]
    assert sum(feet) == pytest.approx(MASS * 9.81, rel=0.10)
    assert min(feet) > 5.0  # both feet flat: heels and toes all loaded
    assert s["heel_l"] + s["heel_r"] > s["toe_l"] + s["toe_r"]  # the ankle is 5 cm from the heel (§7.19)
    assert abs(s["fall"]) < 0.01  # standing still: the centre of mass over the centre of pressure


@pytest.mark.parametrize(
    ("force", "duration", "falls", "direction"),
    [
        (10.0, 0.6, False, 0),  # E4.3's 10 N for about a step (L1270): the stander keeps its feet
        (45.0, 0.1, False, 0),  # E4.4's 45 N (L1319) as a 0.1-s knock (§7.12)
        (45.0, 0.3, True, +1),  # held longer it tips the rigid stander over its toes
        (-45.0, 0.1, True, -1),  # backward: 5 cm of heel behind the ankle
    ],
)
def test_pushes_on_a_pd_stander(force, duration, falls, direction):
    body, result = trial(
        duration=4.0, initial_knee=-0.3, body_params={"push_force": force, "push_time": 1.0, "push_duration": duration}
    )
    assert result.metrics["fell"] is falls and result.metrics["pushed"]
    if falls:
        assert np.sign(body.sense()[SENSOR_NAMES.index("pelvis")]) == direction


def test_a_simple_feedback_gait_walks_10_s_without_a_boom():
    gait = SimpleGait()
    _, result = trial(gait, duration=10.0, initial_knee=-0.2, initial_step=0.25)
    m = result.metrics
    assert result.success and not m["fell"] and m["steps"] >= 10 and m["distance"] > 3.0
    assert result.quality == pytest.approx(0.5 * MASS * m["velocity"] ** 2 / m["energy"])  # (5.7)-(5.8)
    for signal, low, high in zip(SENSORS, gait.low, gait.high, strict=True):
        assert signal.low <= low and high <= signal.high, signal.name


def test_logged_trial_telemetry():
    body = PlanarWalker8(PlanarWalker8.Params(duration=3.0, initial_knee=-0.3))
    body.link = InProcessLink(HoldPosture())
    body.telemetry = sink = CaptureTelemetry()
    push = {"push_force": 60.0, "push_time": 0.5, "push_duration": 0.3}
    result = body.handle(TrialRequest(trial_id=2, seed=0, body_params=push, controller_params={}, log=True))
    assert result.metrics["fell"]
    paths = sink.paths()
    assert {f"joints/{j}" for j in JOINTS} <= paths
    assert {"contacts/heel_l", "contacts/toe_l", "contacts/heel_r", "contacts/toe_r", "walker", "ground"} <= paths
    assert {"push", "events/push", "events/fall", "balance/fall", "balance/pelvis"} <= paths
    hip = next(i for i in sink.of(Scalars) if i.path == "joints/hip_l")
    assert hip.unit == "deg" and hip.trial == 2 and hip.times[0] == pytest.approx(2 * 3.0 + 0.01)
    walker = next(i for i in sink.of(Strips2D) if i.path == "walker")
    assert walker.per_frame == 6 and len(walker.strips) == 6 * len(walker.times)
    assert np.diff(walker.times) == pytest.approx(0.04)  # 25 pictures per simulated second
    (arrows,) = sink.of(Arrows2D)  # while the push acts, at the pictures' 25 per second, pointing forward
    assert len(arrows.times) == 7 and np.all((arrows.times > 6.5) & (arrows.times <= 6.81))
    assert np.all(arrows.vectors == (0.6, 0.0))  # 1 m per 100 N
    (fall,) = [e for e in sink.of(Event) if e.path == "events/fall"]
    assert fall.level == "WARN" and fall.time == pytest.approx(6.0 + result.metrics["fell_at"])
    quiet = PlanarWalker8(PlanarWalker8.Params(duration=0.1))
    quiet.link = InProcessLink(HoldPosture())
    quiet.telemetry = nothing = CaptureTelemetry()
    quiet.handle(TrialRequest(trial_id=0, seed=0, body_params={}, controller_params={}, log=False))
    assert not nothing.items


@pytest.mark.parametrize(
    ("name", "value", "message"),
    [
        ("slope_deg", 20, "slope_deg: expected a number in [-15, 15]; got 20"),
        ("push_force", "strong", "push_force: expected a number; got 'strong'"),
        ("push_duration", -0.1, "push_duration: expected a number in [0, 600]; got -0.1"),
        ("terrain", "1:0,1:30", "terrain '1:0,1:30' piece 1 slope: expected a number in [-15, 15]; got 30.0"),
    ],
)
def test_trial_parameters_are_checked(name, value, message):
    with pytest.raises(ValueError) as err:
        PlanarWalker8.check_trial_param(name, value)
    assert str(err.value) == message
    PlanarWalker8.check_trial_param("terrain", "0.5:0,1:8")
    with pytest.raises(ValueError, match="push_force"):
        trial(duration=0.01, body_params={"push_force": float("nan")})


def test_a_trial_is_the_same_to_the_last_bit_in_every_process():
    """pymunk lists contacts in an order of memory addresses; the body sums them in an order of their values, so a trial
    repeats exactly whatever else a process holds in memory (docs/bodies/planar_8link.md, Reproducibility)."""
    import subprocess
    import sys

    code = """
import numpy as np
from sfl_brain.bodies.planar_8link import PlanarWalker8
from sfl_brain.body import InProcessLink
from sfl_brain.messages import TrialRequest
from sfl_brain.modules.controllers.cpg import CPGController, CPGParams
ballast = [np.zeros(1000) for _ in range({n})]  # another memory layout
body = PlanarWalker8(PlanarWalker8.Params(initial_knee=-0.3, start_noise=0.02))
body.link = InProcessLink(CPGController(CPGParams(circuit="planar_8link")))
m = body.handle(TrialRequest(trial_id=0, seed=3, body_params={{}}, controller_params={{}}, log=False)).metrics
print(repr(m["energy"]), repr(m["distance"]), m["steps"])
"""
    outputs = {
        subprocess.run([sys.executable, "-c", code.format(n=n)], capture_output=True, text=True, check=True).stdout
        for n in (0, 37, 211)
    }
    assert len(outputs) == 1, outputs
