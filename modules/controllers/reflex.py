"""The neural reflexive controller of thesis §3.4 (after Geng, Porr & Wörgötter's RunBot).

Sensor neurons (3.4): rho = 1 / (1 + exp(alpha (theta - phi))).
Motor neurons (3.5):  tau dy/dt = -y + sum_i w_i rho_i,   u = 1 / (1 + exp(alpha_m (theta_m - y))).
Motor voltage (3.6):  V = M (G_E U_E + G_F U_F), G_E = +1, G_F = -1.

Wiring (Fig. 3.7), for each leg i with the other leg j:

(a) ground contact G_i excites the knee extensor EM and the hip flexor FM of leg i (stance);
(b) G_j excites the knee flexor FM and the hip extensor EM of leg i (swing);
(c) articular reflex: each joint's extensor sensor E inhibits its EM, its flexor sensor F its FM;
(d) extension reflex: the hip stretch receptor AS_i excites the knee EM of leg i (and, as in
    RunBot, inhibits the knee FM, so that the swing knee straightens before touch-down).

Hip angles are in RunBot's convention (90 deg = thigh along the trunk, larger = swung forward;
"extension" at RunBot's hip is the forward swing). The learnt parameters are those of the hip
extensor sensor neuron: ``alpha_hip`` (its slope, per radian) and ``theta_hip_max_deg`` (its
threshold: the amplitude of the forward swing).

For the exploit protocol the controller can instead receive a ``switching_table``
(condition -> alpha_hip, theta_hip_max_deg): at every tick it applies the entry whose condition
(the ground slope under the robot, in degrees) is closest, as the success-map neuron switching
of §3.5.2.
"""

from __future__ import annotations

import math

import numpy as np
from pydantic import Field

from sfl_brain.body import Controller
from sfl_brain.module import ModuleParams

# sensor order this controller reads
SENSORS = ("hip_l", "hip_r", "knee_l", "knee_r", "contact_l", "contact_r", "slope")


class ReflexParams(ModuleParams):
    alpha_hip: float = Field(10.0, ge=0, le=100, description="hip extensor sensor slope, 1/rad (learnt)")
    theta_hip_max_deg: float = Field(120.0, ge=60, le=180, description="hip extensor threshold, deg (learnt)")
    theta_hip_min_deg: float = Field(70.0, ge=0, le=120, description="hip flexor sensor threshold, deg")
    alpha_hip_flexor: float = Field(10.0, ge=0, description="hip flexor sensor slope, 1/rad")
    as_lead_deg: float = Field(
        5.0,
        ge=0,
        le=60,
        description="the stretch receptor AS fires this many degrees "
        "before the hip reaches theta_hip_max (RunBot: at the anterior extreme)",
    )
    alpha_as: float = Field(20.0, ge=0, description="stretch receptor slope, 1/rad")
    theta_knee_extended_deg: float = Field(-3.0, description="knee extensor sensor threshold, deg")
    theta_knee_flexed_deg: float = Field(-60.0, description="knee flexor sensor threshold, deg")
    alpha_knee: float = Field(20.0, ge=0, description="knee sensor slope, 1/rad")
    tau: float = Field(0.01, gt=0, description="motor neuron time constant, s (3.5)")
    alpha_motor: float = Field(10.0, gt=0, description="motor neuron slope (3.5)")
    theta_motor: float = Field(0.5, description="motor neuron bias theta_m (3.5)")
    m_hip: float = Field(5.0, ge=0, description="servo amplification M of the hips, V (3.6)")
    m_knee: float = Field(5.0, ge=0, description="servo amplification M of the knees, V (3.6)")
    w_excite: float = Field(1.0, description="weight of excitatory synapses")
    w_inhibit: float = Field(-2.0, description="weight of inhibitory synapses")
    control_dt: float = Field(0.01, gt=0, description="tick length, s (must match the body)")


def sensor_neuron(alpha: float, theta: float, phi):
    """rho = (1 + exp(alpha (theta - phi)))^-1   (3.4)"""
    return 1.0 / (1.0 + np.exp(alpha * (theta - phi)))


class ReflexController(Controller):
    """Reflexive sensor-motor network of §3.4 (eqs. 3.4-3.6, Fig. 3.7); learns alpha_hip, theta_hip_max."""

    Params = ReflexParams
    REQUIRED_SENSORS = SENSORS
    COMMANDS = ("v_hip_l", "v_hip_r", "v_knee_l", "v_knee_r")
    TRIAL_PARAMS = ("alpha_hip", "theta_hip_max_deg", "switching_table")
    #: sensor neurons (3.4), motor neurons (3.5) and ground contacts, per leg, logged on logged trials
    NEURONS = tuple(
        f"{kind}/{name}_{side}"
        for kind, names in (
            ("sensor", ("hip_extensor", "hip_flexor", "stretch_AS", "knee_extensor", "knee_flexor")),
            ("motor", ("hip_EM", "hip_FM", "knee_EM", "knee_FM")),
            ("contact", ("G",)),
        )
        for name in names
        for side in ("l", "r")
    )

    def configure(self, params: dict, seed: int) -> None:
        p = self.params
        table = params.get("switching_table")
        self.table = None
        if table:
            self.table = (
                np.asarray(table["condition"], float),
                np.asarray(table["alpha_hip"], float),
                np.asarray(table["theta_hip_max_deg"], float),
            )
        self.alpha_hip = float(params.get("alpha_hip", p.alpha_hip))
        self.theta_hip_max = math.radians(float(params.get("theta_hip_max_deg", p.theta_hip_max_deg)))
        # motor neuron states y: [hip EM, hip FM, knee EM, knee FM] x [left, right]
        self.y = np.zeros((4, 2))
        self.decay = 1.0 - math.exp(-p.control_dt / p.tau)  # exact integration of (3.5) over one tick
        self.activity = np.zeros((4, 2))
        self.stance = None  # which leg's ground contact fired last (0 left, 1 right)
        self.previous_contact = np.zeros(2)

    def step(self, sensors: np.ndarray) -> np.ndarray:
        p = self.params
        hip = sensors[0:2]
        knee = sensors[2:4]
        ground = sensors[4:6]
        if self.table is not None:
            k = int(np.argmin(np.abs(self.table[0] - math.degrees(sensors[6]))))
            self.alpha_hip = float(self.table[1][k])
            self.theta_hip_max = math.radians(float(self.table[2][k]))
        # ground contact neurons fire on touch-down and hold until the other foot touches down:
        # G_i is 1 for the stance leg, 0 for the swing leg (no ambiguity in double support)
        touchdown = (ground > 0.5) & (self.previous_contact < 0.5)
        if touchdown.any():
            self.stance = int(np.flatnonzero(touchdown)[-1]) if touchdown.sum() == 1 else int(np.argmax(hip))
        elif self.stance is None and ground.any():
            self.stance = int(np.argmax(ground))
        self.previous_contact = ground.copy()
        g_own = np.zeros(2)
        if self.stance is not None:
            g_own[self.stance] = 1.0
        g_other = g_own[::-1]
        # sensor neurons (3.4)
        hip_e = sensor_neuron(self.alpha_hip, self.theta_hip_max, hip)
        hip_f = sensor_neuron(p.alpha_hip_flexor, -math.radians(p.theta_hip_min_deg), -hip)
        stretch = sensor_neuron(p.alpha_as, self.theta_hip_max - math.radians(p.as_lead_deg), hip)
        knee_e = sensor_neuron(p.alpha_knee, math.radians(p.theta_knee_extended_deg), knee)
        knee_f = sensor_neuron(p.alpha_knee, -math.radians(p.theta_knee_flexed_deg), -knee)
        we, wi = p.w_excite, p.w_inhibit
        drive = np.array(
            [
                we * g_other + wi * hip_e,  # hip EM: (b), (c)
                we * g_own + wi * hip_f,  # hip FM: (a), (c)
                we * g_own + we * stretch + wi * knee_e,  # knee EM: (a), (d), (c)
                we * g_other + wi * stretch + wi * knee_f,  # knee FM: (b), (d), (c)
            ]
        )
        self._sensor_neurons = (hip_e, hip_f, stretch, knee_e, knee_f, g_own)
        self.y += self.decay * (drive - self.y)  # (3.5)
        u = 1.0 / (1.0 + np.exp(p.alpha_motor * (p.theta_motor - self.y)))
        self.activity = u
        v_hip = p.m_hip * (u[0] - u[1])  # (3.6), G_E = 1, G_F = -1
        v_knee = p.m_knee * (u[2] - u[3])
        return np.array([v_hip[0], v_hip[1], v_knee[0], v_knee[1]])

    def neurons(self) -> np.ndarray:
        hip_e, hip_f, stretch, knee_e, knee_f, g_own = self._sensor_neurons
        return np.concatenate([hip_e, hip_f, stretch, knee_e, knee_f, self.activity.ravel(), g_own])
