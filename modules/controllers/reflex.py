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


# The ten sensor neurons, [left, right] per kind: hip extensor E, hip flexor F, stretch receptor AS,
# knee extensor E, knee flexor F. Each reads phi = sign * sensors[_PHI] (sensors 0-1 hips, 2-3 knees);
# the flexor sensors read the negated angle.
_PHI = np.array([0, 1, 0, 1, 0, 1, 2, 3, 2, 3])
_SIGN = np.array([1.0, 1.0, -1.0, -1.0, 1.0, 1.0, 1.0, 1.0, -1.0, -1.0])
# The eight motor neurons, [left, right] per kind: hip EM, hip FM, knee EM, knee FM. Their sensor
# inputs (Fig. 3.7 (c), (d)) come in two terms, so that each sum keeps the thesis's order:
_T2 = np.array([0, 1, 2, 3, 4, 5, 4, 5])  # hip E -> hip EM, hip F -> hip FM, AS -> knee EM and knee FM
_T3 = np.array([0, 1, 0, 1, 6, 7, 8, 9])  # knee E -> knee EM, knee F -> knee FM (weight 0 at the hips)
_EM = np.array([0, 1, 4, 5])  # extensor motor neurons of [hip l, hip r, knee l, knee r]
_FM = np.array([2, 3, 6, 7])  # flexor motor neurons of the same joints


def sensor_neuron(alpha, theta, phi):
    """rho = (1 + exp(alpha (theta - phi)))^-1   (3.4), elementwise"""
    return 1.0 / (1.0 + np.exp(alpha * (theta - phi)))


class ReflexController(Controller):
    """Reflexive sensor-motor network of §3.4 (eqs. 3.4-3.6, Fig. 3.7); learns alpha_hip, theta_hip_max."""

    Params = ReflexParams
    READS = SENSORS
    WRITES = ("v_hip_l", "v_hip_r", "v_knee_l", "v_knee_r")
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
        self._entry = -1  # the switching table's entry in force
        # The ten sensor neurons (3.4) in one vector, [left, right] per kind, in NEURONS order:
        # hip extensor E, hip flexor F, stretch receptor AS, knee extensor E, knee flexor F.
        # rho = sensor_neuron(alpha, theta, sign * sensors[_PHI])
        self._alpha = np.repeat([0.0, p.alpha_hip_flexor, p.alpha_as, p.alpha_knee, p.alpha_knee], 2)
        self._theta = np.repeat(
            [
                0.0,
                -math.radians(p.theta_hip_min_deg),
                0.0,
                math.radians(p.theta_knee_extended_deg),
                -math.radians(p.theta_knee_flexed_deg),
            ],
            2,
        )
        self._set_hip_extensor(
            float(params.get("alpha_hip", p.alpha_hip)),
            math.radians(float(params.get("theta_hip_max_deg", p.theta_hip_max_deg))),
        )
        # motor neurons (3.5): [hip EM, hip FM, knee EM, knee FM] x [left, right], drive = (T1 + T2) + T3
        we, wi = p.w_excite, p.w_inhibit
        self._w2 = np.repeat([wi, wi, we, wi], 2)  # T2: hip E, hip F, AS, AS
        self._w3 = np.repeat([0.0, 0.0, wi, wi], 2)  # T3: -, -, knee E, knee F
        # T1, the ground-contact term, for each state of the stance: none, left, right
        own = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
        g = np.concatenate([own[:, ::-1], own, own, own[:, ::-1]], axis=1)  # (b), (a), (a), (b)
        self._t1 = we * g
        self._g_own = own
        self._m = np.repeat([p.m_hip, p.m_knee], 2)
        self.y = np.zeros(8)
        self.decay = 1.0 - math.exp(-p.control_dt / p.tau)  # exact integration of (3.5) over one tick
        self.activity = np.zeros(8)
        self._rho = np.zeros(10)
        self.stance = None  # which leg's ground contact fired last (0 left, 1 right)
        self.previous_contact = (0.0, 0.0)

    def _set_hip_extensor(self, alpha_hip: float, theta_hip_max: float) -> None:
        """The learnt parameters: slope and threshold of the hip extensor sensor; AS fires before it."""
        self.alpha_hip, self.theta_hip_max = alpha_hip, theta_hip_max
        self._alpha[0:2] = alpha_hip
        self._theta[0:2] = theta_hip_max
        self._theta[4:6] = theta_hip_max - math.radians(self.params.as_lead_deg)

    def step(self, sensors: np.ndarray) -> np.ndarray:
        p = self.params
        if self.table is not None:
            k = int(np.argmin(np.abs(self.table[0] - math.degrees(sensors[6]))))
            if k != self._entry:
                self._entry = k
                self._set_hip_extensor(float(self.table[1][k]), math.radians(float(self.table[2][k])))
        # ground contact neurons fire on touch-down and hold until the other foot touches down:
        # G_i is 1 for the stance leg, 0 for the swing leg (no ambiguity in double support)
        hip_l, hip_r, _, _, ground_l, ground_r = sensors[:6].tolist()
        was_l, was_r = self.previous_contact
        down_l, down_r = ground_l > 0.5 and was_l < 0.5, ground_r > 0.5 and was_r < 0.5
        if down_l or down_r:
            self.stance = (0 if down_l else 1) if down_l != down_r else int(hip_r > hip_l)
        elif self.stance is None and (ground_l or ground_r):
            self.stance = int(ground_r > ground_l)
        self.previous_contact = (ground_l, ground_r)
        # sensor neurons (3.4)
        rho = self._rho = sensor_neuron(self._alpha, self._theta, sensors[_PHI] * _SIGN)
        # motor neurons (3.5): Fig. 3.7's synapses (a)-(d), then exact integration over the tick
        drive = (self._t1[0 if self.stance is None else self.stance + 1] + self._w2 * rho[_T2]) + self._w3 * rho[_T3]
        self.y += self.decay * (drive - self.y)
        u = self.activity = 1.0 / (1.0 + np.exp(p.alpha_motor * (p.theta_motor - self.y)))
        return self._m * (u[_EM] - u[_FM])  # (3.6), G_E = 1, G_F = -1: [hip l, hip r, knee l, knee r]

    def neurons(self) -> np.ndarray:
        stance = 0 if self.stance is None else self.stance + 1
        return np.concatenate([self._rho, self.activity, self._g_own[stance]])
