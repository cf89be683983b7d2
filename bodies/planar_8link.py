"""The 8-link planar walker of thesis Fig. 4.7 (L1192), on pymunk, with no boom.

"The simulated robot's mass is 22 kg. The body part lengths are: 10 cm for the trunk, 16 cm for the
pelvis, 40 cm for the tibia, 40 cm for the thigh, and 20 cm for the foot" (L1192); "Each joint is
driven by a simulated servo motor" (L1201). Links: trunk, pelvis, and per leg thigh, tibia (shank),
foot = 8; joints: trunk (trunk-pelvis), hips, knees, ankles = 7. The digest (CPG-HUMANOID.md) is
cited as §.

Not in the thesis, chosen as the digest recommends (§7.19): masses trunk 9, pelvis 4, thigh 2.5,
tibia 1.5, foot 0.5 kg (= 22 kg); the ankle 5 cm from the heel. Chosen here: the ankle 3 cm above
the sole (the foot a 20 x 3 cm box, the ankle on its top face, so the leg is 83 cm from hip to sole);
links are uniform (centre of mass at mid-length); the trunk and pelvis boxes 14 cm wide (a picture of
a body, their width only sets their inertia). The pelvis stands upright on the hips, the trunk on
the pelvis: "the objective of [the trunk] controller is to keep [the] pelvis link close with the
vertical" (L1221).

Contact: each foot touches the ground only with a heel disc and a toe disc (1.5 cm radius, at the
foot's ends), so the heel and toe normal forces are the two sensors GB and GF of Fig. 4.7 / Fig. 4.10
(L1212); the other links have shapes too, and any of them touching the ground is a fall. Coulomb
friction 0.8 (chosen here: rubber soles on a floor).

Joint angles, rad, 0 = standing straight (the trunk and pelvis upright, legs straight, feet flat),
positive = extension, as the CPG circuit ``modules/cpg/circuits/planar_8link.yaml`` fixes them:

* ``hip``: extension = the thigh swung back behind the pelvis axis (flexion = thigh forward);
* ``knee``: extension = straightening; 0 is straight and the knee cannot over-extend, so it is <= 0;
* ``ankle``: extension = plantar flexion (toe down, the push-off), flexion = dorsiflexion (shin over
  the toes);
* ``trunk``: extension = the trunk leaning back relative to the pelvis (as a lumbar extension).

Joint stops (rad, the circuit's ES/FS ranges, "human-like, chosen" there): hip [-0.6, 0.4], knee
[-1.2, 0], ankle [-0.35, 0.35], trunk [-0.3, 0.3].

Motors: every joint has the same geared DC motor, the servo of L1201. The command is its voltage V
((3.6), L874), clipped to +-MAX_VOLTAGE; the torque is tau = k_t (V - k_t omega) / R (k_t the torque
constant = back-EMF constant, joint side, SI; omega the joint speed), so the motor itself limits the
torque (stall, k_t V_max / R = 72 N m) and the speed (no load, V_max / k_t = 8 rad/s). Chosen here
(the thesis gives no motor data): 6 N m per volt, so the circuit's 5-V gain (M of (3.6)) gives up
to 30 N m, several times what standing needs at a hip or an ankle (22 kg x 9.81 x 5 cm = 11 N m),
and the back-EMF damping k_t^2 / R = 9 N m s / rad settles a swinging leg (about 1 kg m^2 at the hip)
in about 0.1 s. The -k_t^2 omega / R part is an implicit damper in the solver (as ``planar_biped``):
stable at any step. The electrical power is R I^2 with I = (V - k_t omega) / R, summed over the
motors and integrated into E_e ((5.5)-(5.6)); a back-driven motor with V = 0 dissipates too.

Sensors besides the angles (Fig. 4.7, L1212, L1221): heel and toe normal forces per foot (N, the mean
over the tick's physics steps, as a force sensor read every tick), ``fall`` = centre of mass minus
centre of pressure along the horizontal (m, + = the centre of mass ahead: falling forward; with no
foot on the ground the feet's midpoint stands in for the centre of pressure), ``pelvis`` = the pelvis
axis' angle to the vertical (rad, + = leaning forward), its rate, the ground slope under the hip, and
the joint speeds, and ``back``: the force pressing on the trunk's back over the last tick (N; a touch sensor, chosen
here: it tells a controller a push has come, as a perfect push detector would, for E4.4's switch). Speeds, forces and
``fall`` saturate at their declared bounds.

Pushes (E4.3, E4.4, L1270, L1319): a horizontal force ``push_force`` (N, + = forward, i.e. on the
back) at the trunk's centre of mass from ``push_time`` for ``push_duration`` s, or at a phase of the gait that the
body measures itself (chosen here; the thesis gives no timing):

* a left heel strike is the left heel force (the tick's mean, as sensed) rising through ``heel_strike`` (50 N, GB_l's
  threshold in the circuit); a rise within ``strike_refractory`` (0.4 s) of the last strike is the same landing
  bouncing. The first tick's stance is no strike. ``heel_strikes`` lists their times (s).
* the gait period T is the median interval of the left heel strikes from ``gait_from`` (2 s, past the start's
  transient) up to the moment it is needed, from at least 2 intervals (3 strikes);
* ``push_phase`` p in [0, 1): the push starts at the first left heel strike at or after ``push_time`` by which T is
  measured (the strike included), plus p T;
* ``push_steps`` n (instead of ``push_duration``): the push lasts n T / 2 (a step = half a cycle, digest §7.12); with
  no ``push_phase`` it starts at ``push_time`` and T is measured then.

The push acts on whole control ticks: on the ticks whose start t satisfies onset <= t < onset + length (1e-9 s of
slack), so the onset and length are rounded to the tick. If T cannot be measured (the walker fell or stands) or the
onset comes after the trial's end, there is no push, and the trial is judged as any other. A trial that asks for a
push (a force and a length) reports ``push_onset`` (s, the first pushed tick; None if none), ``push_duration`` (s,
the pushed ticks x the tick), ``push_impulse`` (N s, force x that duration), ``push_anchor`` (s, the strike the
phase counts from; None without ``push_phase``), ``gait_period`` (s, the T used; for a push at a time, T measured up
to its onset; None if too few strikes) and ``push_missed`` (no tick was pushed); an unpushed trial reports only
the metrics it always did.

A trial ends with a fall (the digest's humanoid rule, §7.14: the hip below half its standing height,
or the pelvis tilted beyond 45 deg; here also any link but a foot on the ground) or at ``duration``.
Success (E4.2, L1243): the walker "did not fall during the time window and achieved two steps at
least" (the window: ``duration``, 10 s); a step is a foot landing
(its heel + toe force rising through 10 % of body weight) ahead of the other foot, the feet
alternating. Quality eta: walking efficiency (5.7)-(5.8), kinetic energy at the mean speed over E_e.

Start: standing, feet flat, pelvis and trunk upright, at rest; ``initial_knee`` bends the knees
(hips and ankles half as much, the hip above the ankles), ``initial_step`` puts the left foot ahead.
``start_noise`` (chosen here, as the humanoid's, for experiments over seeds: E4.3, E4.4) makes the start differ by
the trial seed: a normal offset of that s.d. added to the crouch (rad) and a forward speed of all links (m/s). It
changes the walker's state, not its timing: under the CPG the heel strikes after 4 s fall within 10-70 ms of each
other over seeds whatever the noise (0.02 or 0.1; the rhythm generators start from the same kick at t = 0 and heel
contact only resets them weakly), while the step length and speed at a strike differ (0.47-0.55 m, 0.86-1.03 m/s
at 0.02). See docs/bodies/planar_8link.md.

``PlanarWalker8Servo`` (registered as ``planar_8link_servo``) is the same walker with a position servo per joint,
the servo of L1201 taken literally: its commands are target angles ``q_<joint>`` (rad, clipped to the joint's stops),
and every control tick the servo sets the same DC motor's voltage to V = clip(K_p (q_cmd - q) - K_d omega, +-12 V)
(q, omega: the joint's angle and speed at the tick's start), so the torque, the back-EMF and the energy E_e are the
voltage walker's and the two compare. K_p = 30 V/rad (180 N m/rad, just above the 166 N m/rad gravity asks at the
ankles of the 22-kg walker, m g h with h = 0.77 m), K_d = 0: the motor's own back-EMF (9 N m s/rad) damps it; on a
light link the servo behaves as a first-order loop closing K_p / k_t = 20 per s, stable at the 10-ms tick up to
K_p = 2 k_t / tick = 300 V/rad, and a K_d on the tick-old speed is stable only below k_t = 1.5 V s/rad. K_p came
with the circuit ``modules/cpg/circuits/planar_8link_servo.yaml`` from a search over 30, 50 and 100 V/rad: stiffer
servos did not walk (100: no configuration of 181). Its ``strike_refractory`` is 0.6 s: this walker's heel can land
twice in a cycle, about 0.5 s apart.

Physics: pymunk, 10 steps of 1 ms per 10-ms control tick, 20 solver iterations (chosen by probing:
with fewer, the joints of the 9-kg trunk over 0.5-kg feet go soft and a standing walker rocks onto its
heels; see docs/bodies/planar_8link.md). The torques and the push are written to every link in one
batch call per physics step, the contacts read in one per step, the state once per tick.

Terrain: a constant ``slope_deg`` or a profile ``terrain`` (as ``planar_biped``), within +-15 deg
(the ankle stops allow standing flat-footed on 20 deg).
"""

from __future__ import annotations

import math
from typing import ClassVar

import numpy as np
import pymunk
import pymunk.batch
from pydantic import Field

from sfl_brain.bodies.planar_biped import parse_terrain
from sfl_brain.body import Body, BodyParams, check_number, walking_efficiency
from sfl_brain.messages import TrialRequest
from sfl_brain.signals import Signal
from sfl_brain.telemetry import Arrows2D, Event, Strips2D, rates_of, series

# --- the body (Fig. 4.7, L1192; masses §7.19) ---------------------------------------------------
TRUNK, PELVIS, THIGH, SHANK, FOOT = 0.10, 0.16, 0.40, 0.40, 0.20  # link lengths, m (L1192)
M_TRUNK, M_PELVIS, M_THIGH, M_SHANK, M_FOOT = 9.0, 4.0, 2.5, 1.5, 0.5  # kg (§7.19), total 22 (L1192)
MASS = M_TRUNK + M_PELVIS + 2 * (M_THIGH + M_SHANK + M_FOOT)
BODY_WIDTH = 0.14  # trunk and pelvis boxes, m: chosen here, sets only their inertia
FOOT_THICK = 0.03  # m, chosen here: the ankle on the top face of a 3 cm foot
HEEL_TO_ANKLE = 0.05  # m (§7.19)
TOE_R = 0.015  # heel and toe contact discs, m (half the foot's thickness)
LEG = THIGH + SHANK + FOOT_THICK  # hip to sole, standing straight: 0.83 m
GROUND_R = 0.01  # ground segments' radius: the surface is this far above the profile
G = 9.81

#: foot-local points (origin at the foot box's centre, x toward the toe): ankle, heel disc, toe disc
ANKLE_LOCAL = (-FOOT / 2 + HEEL_TO_ANKLE, FOOT_THICK / 2)
HEEL_LOCAL = (-FOOT / 2 + TOE_R, 0.0)
TOE_LOCAL = (FOOT / 2 - TOE_R, 0.0)

# joint stops, rad (the circuit file's ES/FS ranges); sensors report within them +- STOP_SLACK
HIP_LIMITS, KNEE_LIMITS, ANKLE_LIMITS, TRUNK_LIMITS = (-0.6, 0.4), (-1.2, 0.0), (-0.35, 0.35), (-0.3, 0.3)
STOP_SLACK = 0.05  # rad: stops are constraints of an iterative solver and give a little under impact
MAX_VOLTAGE = 12.0  # V, commands are clipped to +-this (chosen here, a 12-V servo supply)
MAX_SLOPE_DEG = 15.0
MAX_SPEED = 30.0  # rad/s: joint-speed and pelvis-rate sensors saturate here
MAX_FORCE = 2000.0  # N: contact force sensors saturate here (about 9 body weights)
MAX_FALL = 1.0  # m: the fall sensor saturates here

# links, in the rows of every per-link array
LINKS = ("trunk", "pelvis", "thigh_l", "shank_l", "foot_l", "thigh_r", "shank_r", "foot_r")
TRUNK_ROW, PELVIS_ROW, FOOT_ROWS = 0, 1, (4, 7)
# joints, in COMMANDS order: (parent link, child link, sign); angle = sign (child - parent) world angles
# (pymunk angles are counter-clockwise and the walker faces +x, so a thigh swung forward turns +)
JOINTS = (
    ("trunk", 1, 0, +1, TRUNK_LIMITS),  # trunk leaning back on the pelvis = extension
    ("hip_l", 1, 2, -1, HIP_LIMITS),  # thigh behind the pelvis = extension
    ("hip_r", 1, 5, -1, HIP_LIMITS),
    ("knee_l", 2, 3, +1, KNEE_LIMITS),  # shank behind the thigh = flexion (negative)
    ("knee_r", 5, 6, +1, KNEE_LIMITS),
    ("ankle_l", 3, 4, -1, ANKLE_LIMITS),  # toe down = extension (plantar flexion)
    ("ankle_r", 6, 7, -1, ANKLE_LIMITS),
)
_PARENT = np.array([j[1] for j in JOINTS])
_CHILD = np.array([j[2] for j in JOINTS])
_SIGN = np.array([float(j[3]) for j in JOINTS])
#: link torques from joint torques (+ = extension): the child gets sign tau, the parent -sign tau
_TORQUE_MAP = np.zeros((len(LINKS), len(JOINTS)))
for _j, (_name, _parent, _child, _sign, _limits) in enumerate(JOINTS):
    _TORQUE_MAP[_child, _j] += _sign
    _TORQUE_MAP[_parent, _j] -= _sign
_LINK_MASS = np.array([M_TRUNK, M_PELVIS, M_THIGH, M_SHANK, M_FOOT, M_THIGH, M_SHANK, M_FOOT])


def _bounds(limits: tuple[float, float]) -> tuple[float, float]:
    return limits[0] - STOP_SLACK, limits[1] + STOP_SLACK


_MEANING = {
    "trunk": "trunk on the pelvis: + = leaning back (extension), 0 = upright",
    "hip": "hip: + = thigh behind the pelvis (extension), - = thigh forward, 0 = straight",
    "knee": "knee: 0 = straight, - = flexed",
    "ankle": "ankle: + = toe down (plantar flexion), - = shin over the toes, 0 = foot square",
}
_SIDE = {"l": "left ", "r": "right "}
SENSORS = (
    *(
        Signal(name, "rad", *_bounds(limits), _SIDE.get(name[-1], "") + _MEANING[name.split("_")[0]])
        for name, _, _, _, limits in JOINTS
    ),
    Signal("heel_l", "N", 0.0, MAX_FORCE, "left heel normal contact force (GB, Fig. 4.7)"),
    Signal("toe_l", "N", 0.0, MAX_FORCE, "left toe normal contact force (GF)"),
    Signal("heel_r", "N", 0.0, MAX_FORCE, "right heel normal contact force (GB)"),
    Signal("toe_r", "N", 0.0, MAX_FORCE, "right toe normal contact force (GF)"),
    Signal(
        "fall",
        "m",
        -MAX_FALL,
        MAX_FALL,
        "centre of mass minus centre of pressure, horizontal, + = ahead (FB/FF, L1212)",
    ),
    Signal("pelvis", "rad", -math.pi, math.pi, "pelvis axis to the vertical, + = leaning forward (BS/BF, L1221)"),
    Signal("pelvis_rate", "rad/s", -MAX_SPEED, MAX_SPEED, "d pelvis / dt, + = tipping forward"),
    Signal("slope", "rad", -math.radians(MAX_SLOPE_DEG), math.radians(MAX_SLOPE_DEG), "ground under the hip, uphill +"),
    *(Signal(f"{j[0]}_speed", "rad/s", -MAX_SPEED, MAX_SPEED, f"d {j[0]} / dt, + = extending") for j in JOINTS),
    Signal("back", "N", 0.0, 1000.0, "force pressing on the trunk's back over the last tick (a touch sensor: a push)"),
)
COMMANDS = tuple(
    Signal(f"v_{j[0]}", "V", -MAX_VOLTAGE, MAX_VOLTAGE, f"{j[0]} motor voltage (3.6), + = extend, clipped")
    for j in JOINTS
)
_N_ANGLES = len(JOINTS)

# the walker's picture: 6 strips of 4 points per frame (see _picture_points; strips of one length go as one
# array, a shorter strip repeats its last point): trunk, pelvis, left leg, left foot, right leg, right foot
_STRIPS = np.array([[0, 1, 1, 1], [1, 2, 2, 2], [2, 3, 4, 4], [4, 5, 6, 4], [2, 7, 8, 8], [8, 9, 10, 8]])
_PICTURE_LINKS = np.array([0, 1, 1, 2, 4, 4, 4, 5, 7, 7, 7])  # the link of each picture point
_PICTURE_LOCAL = np.array(  # each point in its link's frame, m
    [
        (0, TRUNK / 2),
        (0, PELVIS / 2),
        (0, -PELVIS / 2),
        (0, -THIGH / 2),
        ANKLE_LOCAL,
        (-FOOT / 2, -FOOT_THICK / 2),
        (FOOT / 2, -FOOT_THICK / 2),
        (0, -THIGH / 2),
        ANKLE_LOCAL,
        (-FOOT / 2, -FOOT_THICK / 2),
        (FOOT / 2, -FOOT_THICK / 2),
    ]
)
_GROUND_COLOR = np.array([(120, 100, 80)], dtype=np.uint8)
_COLORS = np.array(
    [(90, 90, 90), (60, 60, 60), (40, 110, 220), (40, 110, 220), (230, 140, 30), (230, 140, 30)], dtype=np.uint8
)

_BF = pymunk.batch.BodyFields
_AF = pymunk.batch.ArbiterFields
_ARBITER_FIELDS = _AF.BODY_A_ID | _AF.BODY_B_ID | _AF.TOTAL_IMPULSE | _AF.NORMAL | _AF.POINT_A_1 | _AF.POINT_B_1


TRIAL_LIMITS = {  # name: (low, high) of each numeric trial parameter
    "slope_deg": (-MAX_SLOPE_DEG, MAX_SLOPE_DEG),
    "push_force": (-1000.0, 1000.0),  # N
    "push_time": (0.0, 600.0),  # s
    "push_duration": (0.0, 600.0),  # s
    "push_phase": (0.0, 1.0),  # of the measured gait cycle, 1 excluded (check_trial_param)
    "push_steps": (0.0, 100.0),  # steps of T / 2
}
MIN_GAIT_INTERVALS = 2  # left heel strike intervals the gait period T is the median of, at least


class PlanarWalker8Params(BodyParams):
    substeps: int = Field(10, ge=1, le=100, description="physics steps per control tick (1 ms at 10)")
    iterations: int = Field(20, ge=1, le=200, description="pymunk solver iterations per physics step")
    torque_constant: float = Field(
        1.5, gt=0, description="k_t, N m / A = back-EMF V s / rad, joint side (chosen: 72 N m stall at 12 V)"
    )
    resistance: float = Field(0.25, gt=0, description="R: winding resistance, ohm (chosen: k_t / R = 6 N m / V)")
    friction: float = Field(0.8, ge=0, description="Coulomb friction of the soles and the ground")
    min_steps: int = Field(2, ge=0, description="steps needed for a success (E4.2, L1243)")
    fall_height: float = Field(0.5, gt=0, lt=1, description="a fall: hip below this fraction of standing (§7.14)")
    fall_tilt_deg: float = Field(45.0, gt=0, le=90, description="a fall: pelvis tilted beyond this (§7.14)")
    step_load: float = Field(0.1, gt=0, lt=1, description="a foot lands when its force rises through this x weight")
    initial_step: float = Field(0.0, ge=0, le=0.6, description="m: the left ankle starts this far ahead of the right")
    initial_knee: float = Field(
        0.0, ge=-1.0, le=0.0, description="rad: knee angle at the start (hips and ankles flex half as much each)"
    )
    start_noise: float = Field(
        0.0,
        ge=0,
        le=0.2,
        description="s.d. of the start's offsets, drawn from the trial seed: the crouch (rad, added to initial_knee) "
        "and the whole walker's forward speed (m/s); 0 = the same start every trial",
    )
    heel_strike: float = Field(
        50.0,
        gt=0,
        le=MAX_FORCE,
        description="N: a left heel strike is the left heel force rising through this (GB_l's threshold in the "
        "circuit; the gait phase of push_phase counts from these strikes)",
    )
    strike_refractory: float = Field(
        0.4, ge=0, le=5, description="s: a heel force rising again within this of the last strike is the same landing"
    )
    gait_from: float = Field(
        2.0, ge=0, le=600, description="s: the gait period T is measured from the left heel strikes from this time on"
    )


class PlanarWalker8(Body):
    """The 8-link planar walker of Fig. 4.7: 22 kg, 7 DC-servo joints, heel/toe force sensors, no boom."""

    Params = PlanarWalker8Params
    SENSORS = SENSORS
    COMMANDS = COMMANDS
    TRIAL_PARAMS = ("slope_deg", "terrain", "push_force", "push_time", "push_duration", "push_phase", "push_steps")

    #: keep this trial's samples for log_trial (Body.trial sets it per trial: a logged trial with a sink)
    logging = False

    @classmethod
    def check_trial_param(cls, name: str, value) -> None:
        """Raise ValueError if ``value`` cannot be trial parameter ``name`` (``sfl check`` calls this)."""
        if name == "terrain":
            for k, (_, slope) in enumerate(parse_terrain(value)):
                check_number(f"terrain {value!r} piece {k} slope", slope, -MAX_SLOPE_DEG, MAX_SLOPE_DEG)
        elif name == "push_phase":  # [0, 1): a phase of 1 is the next cycle's 0
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ValueError(f"{name}: expected a number; got {value!r}")
            if not (math.isfinite(value) and 0.0 <= value < 1.0):
                raise ValueError(f"{name}: expected a number in [0, 1); got {value!r}")
        elif name in TRIAL_LIMITS:
            check_number(name, value, *TRIAL_LIMITS[name])

    # ------------------------------------------------------------------ world
    def start_trial(self, request: TrialRequest) -> None:
        p = self.params
        given = request.body_params
        for name in sorted(TRIAL_LIMITS.keys() & given.keys()):
            self.check_trial_param(name, given[name])
        if given.get("terrain"):
            self.check_trial_param("terrain", given["terrain"])
            self.pieces = [(length, math.radians(s)) for length, s in parse_terrain(given["terrain"])]
        else:
            self.pieces = [(60.0, math.radians(float(given.get("slope_deg", 0.0))))]
        self._plan_push(given)
        space = pymunk.Space()
        space.gravity = (0.0, -G)
        space.iterations = p.iterations
        space.collision_slop = 0.0005
        self.space = space
        self._build_ground()
        knee, speed = p.initial_knee, 0.0
        if p.start_noise > 0:  # as the humanoid's start_noise: the trial seed draws the start (E4.3, E4.4 seeds)
            offsets = np.random.default_rng(request.seed).normal(0.0, p.start_noise, 2)
            knee, speed = min(max(knee + float(offsets[0]), -1.0), 0.0), float(offsets[1])
        self._build_walker(x_hip=0.3, knee=knee)
        for link in self.links:
            link.velocity = (speed, 0.0)
        self._batch_buffers()
        self.t = 0.0
        self.energy = 0.0
        self.fell = False
        self.fell_at: float | None = None
        self.fall_reason = ""
        self.steps = 0
        self.pushed = False
        self._back = 0.0  # N on the trunk's back over the last tick (the sensor `back`)
        self._push_ticks = 0  # control ticks the push acted on
        self._push_first: float | None = None  # s: the start of the first of them
        #: s: the left heel strikes (heel force rising through ``heel_strike``, ``strike_refractory`` apart)
        self.heel_strikes: list[float] = []
        self._heel_on: bool | None = None  # the left heel above heel_strike at the last tick (None: no tick yet)
        self._last_step_foot = -1
        self._read_state()
        self._read_contacts()
        self._loaded = self._foot_force > p.step_load * MASS * G  # the start's stance is no step
        self.x_start = self._hip_x()
        # a logged trial keeps, every `_log_every` ticks (the sink's rates), the tick, the links' x, y, angle,
        # the sensor values, the voltages and whether the push was on (see log_trial); nothing else per tick
        self._tick = 0
        self._log: list[np.ndarray] | None = [] if self.logging else None
        self._log_every = rates_of(self.telemetry).sample_every(p.control_dt) if self.logging else 0

    def _plan_push(self, given: dict) -> None:
        """This trial's push from its parameters (checked): at a time (``push_time``, ``push_duration``), or at a gait
        phase (``push_phase``) and/or for a number of steps (``push_steps``), then placed by ``_watch_gait``."""
        if "push_steps" in given and "push_duration" in given:
            raise ValueError(
                f"push_steps: expected push_steps or push_duration; got both ({given['push_steps']!r}, "
                f"{given['push_duration']!r})"
            )
        self.push_force = float(given.get("push_force", 0.0))
        self.push_time = float(given.get("push_time", 0.0))
        self.push_duration = float(given.get("push_duration", 0.0)) if self.push_force else 0.0
        self.push_phase = float(given["push_phase"]) if "push_phase" in given else None
        self.push_steps = float(given["push_steps"]) if "push_steps" in given else None
        length = self.push_steps if self.push_steps is not None else self.push_duration
        #: a push was asked for: a force, and a length (s or steps)
        self.push_requested = bool(self.push_force) and length > 0
        #: its onset or length comes from the gait this trial measures (the left heel strikes)
        self.push_on_gait = self.push_requested and (self.push_phase is not None or self.push_steps is not None)
        self.gait_period: float | None = None  # s: T, the median left heel strike interval (from gait_from on)
        self.push_anchor: float | None = None  # s: the left heel strike push_phase counts from
        self._push_placed = not self.push_on_gait  # False until _watch_gait has placed it (or given up)
        if self.push_on_gait:
            self._push_start = self._push_end = math.inf
        else:
            self._push_start, self._push_end = self.push_time, self.push_time + self.push_duration

    def _build_ground(self) -> None:
        """Static segments along the profile: a run-in behind x = 0, the pieces, a run-out of 60 m."""
        first, last = self.pieces[0][1], self.pieces[-1][1]
        xs, ys = [-2.0, 0.0], [-2.0 * math.tan(first), 0.0]
        slopes = [first]
        for length, slope in self.pieces:
            xs.append(xs[-1] + length * math.cos(slope))
            ys.append(ys[-1] + length * math.sin(slope))
            slopes.append(slope)
        xs.append(xs[-1] + 60.0)
        ys.append(ys[-1] + 60.0 * math.tan(last))
        slopes.append(last)
        self.ground_x, self.ground_y, self.ground_slopes = np.array(xs), np.array(ys), np.array(slopes)
        for i in range(len(xs) - 1):
            seg = pymunk.Segment(self.space.static_body, (xs[i], ys[i]), (xs[i + 1], ys[i + 1]), GROUND_R)
            seg.friction = self.params.friction
            self.space.add(seg)

    def ground_height(self, x):
        return np.interp(x, self.ground_x, self.ground_y)

    def ground_slope(self, x):
        i = np.clip(np.searchsorted(self.ground_x, x) - 1, 0, len(self.ground_slopes) - 1)
        return self.ground_slopes[i]

    def _link(self, mass: float, size: tuple[float, float], centre, angle: float, shapes: list) -> pymunk.Body:
        """A uniform box link of ``size`` (width, length along its axis) at ``centre``, with ``shapes``."""
        body = pymunk.Body(mass, pymunk.moment_for_box(mass, size))
        body.position = centre
        body.angle = angle
        for s in shapes:
            s.body = body
            s.filter = pymunk.ShapeFilter(group=1)  # the walker does not collide with itself
            s.friction = self.params.friction
        self.space.add(body, *shapes)
        return body

    def _rod(self, mass: float, length: float, top, angle: float) -> pymunk.Body:
        """A leg segment hanging from ``top`` at world angle ``angle`` (0 = straight down)."""
        half = length / 2
        centre = pymunk.Vec2d(*top) + pymunk.Vec2d(0, -half).rotated(angle)
        return self._link(mass, (0.04, length), centre, angle, [pymunk.Segment(None, (0, half), (0, -half), 0.02)])

    def _build_walker(self, x_hip: float, knee: float) -> None:
        """Standing, feet flat on the ground, pelvis and trunk upright; the left ankle ``initial_step``
        ahead of the right; the hip as high as both legs reach with their knees bent ``knee``,
        each leg's knee then bent as its ankle needs (two-link inverse kinematics)."""
        p = self.params
        ankles = []
        for dx in (p.initial_step / 2, -p.initial_step / 2):
            x = x_hip + dx
            slope = float(self.ground_slope(x))
            # the sole flat on the surface (GROUND_R above the profile), the ankle FOOT_THICK above it
            up = pymunk.Vec2d(-math.sin(slope), math.cos(slope))
            ankle = pymunk.Vec2d(x, float(self.ground_height(x))) + up * (GROUND_R + FOOT_THICK)
            ankles.append((ankle, slope))
        reach = THIGH + SHANK
        bent = reach * math.cos(knee / 2)  # hip to ankle with the knee at ``knee`` (initial_knee, noised)
        hip_y = min(a.y + math.sqrt(max(bent**2 - (a.x - x_hip) ** 2, 0.0)) for a, _ in ankles)
        hip = pymunk.Vec2d(x_hip, hip_y)
        pelvis = self._link(
            M_PELVIS,
            (BODY_WIDTH, PELVIS),
            hip + (0, PELVIS / 2),
            0.0,
            [pymunk.Poly.create_box(None, (BODY_WIDTH, PELVIS))],
        )
        top = hip + (0, PELVIS)
        trunk = self._link(
            M_TRUNK, (BODY_WIDTH, TRUNK), top + (0, TRUNK / 2), 0.0, [pymunk.Poly.create_box(None, (BODY_WIDTH, TRUNK))]
        )
        links = [trunk, pelvis]
        for ankle, slope in ankles:
            d = ankle - hip
            gamma = math.atan2(d.x, -d.y)  # leg direction from straight down
            beta = math.acos(min(1.0, d.length / reach))  # half the knee bend (equal thigh and shank)
            thigh = self._rod(M_THIGH, THIGH, hip, gamma + beta)  # knee forward of the hip-ankle line
            knee = hip + pymunk.Vec2d(0, -THIGH).rotated(gamma + beta)
            shank = self._rod(M_SHANK, SHANK, knee, gamma - beta)
            ankle_at = knee + pymunk.Vec2d(0, -SHANK).rotated(gamma - beta)
            foot_centre = ankle_at - pymunk.Vec2d(*ANKLE_LOCAL).rotated(slope)
            foot = self._link(
                M_FOOT,
                (FOOT, FOOT_THICK),
                foot_centre,
                slope,
                [pymunk.Circle(None, TOE_R, HEEL_LOCAL), pymunk.Circle(None, TOE_R, TOE_LOCAL)],
            )
            links += [thigh, shank, foot]
        self.links = links
        # joints: pivots, stops, and each motor's back-EMF as an implicit damper k_t^2 / R (see the docstring)
        damping = p.torque_constant**2 / p.resistance
        (_, _, thigh_l, _, foot_l, thigh_r, _, foot_r) = links
        knees = [thigh.local_to_world((0, -THIGH / 2)) for thigh in (thigh_l, thigh_r)]
        ankles_at = [foot.local_to_world(ANKLE_LOCAL) for foot in (foot_l, foot_r)]
        for (_, parent, child, sign, limits), at in zip(JOINTS, [top, hip, hip, *knees, *ankles_at], strict=True):
            a, b = links[parent], links[child]
            low, high = limits if sign > 0 else (-limits[1], -limits[0])  # on b.angle - a.angle
            self.space.add(
                pymunk.PivotJoint(a, b, at),
                pymunk.RotaryLimitJoint(a, b, low, high),
                pymunk.DampedRotarySpring(a, b, 0.0, 0.0, damping),
            )

    def _batch_buffers(self) -> None:
        """Buffers for pymunk's batch API: torques and the push go to every link in one call per physics
        step, state and contacts come back in one call each per tick. Rows follow the space's body order."""
        ids = pymunk.batch.Buffer()
        pymunk.batch.get_space_bodies(self.space, _BF.BODY_ID, ids)
        order = {int(i): k for k, i in enumerate(np.frombuffer(ids.int_buf(), dtype=np.uintp))}
        self._rows = np.array([order[b.id] for b in self.links])  # batch row of each link (LINKS order)
        self._foot_ids = [np.uintp(self.links[k].id) for k in FOOT_ROWS]
        self._wrench = np.zeros((len(order), 3))  # per batch row: force x, y (N), torque (N m)
        self._wrench_buffer = pymunk.batch.Buffer()
        self._wrench_buffer.set_float_buf(self._wrench)  # the buffer reads the array: write it in place
        self._state_buffer = pymunk.batch.Buffer()
        self._arbiter_buffer = pymunk.batch.Buffer()

    _STATE_FIELDS = _BF.POSITION | _BF.ANGLE | _BF.ANGULAR_VELOCITY  # x, y, angle, angular velocity

    def _read_state(self) -> None:
        buffer = self._state_buffer
        buffer.clear()
        pymunk.batch.get_space_bodies(self.space, self._STATE_FIELDS, buffer)
        state = self._state = np.frombuffer(buffer.float_buf()).reshape(-1, 4)[self._rows]  # LINKS order
        # joint angles (rad) and speeds (rad/s), COMMANDS order, + = extension
        self._angles = _SIGN * (state[_CHILD, 2] - state[_PARENT, 2])
        self._speeds = _SIGN * (state[_CHILD, 3] - state[_PARENT, 3])

    def _read_contacts(self, ids: bytes = b"", data: bytes = b"") -> None:
        """Heel and toe normal forces of each foot (N), the centre of pressure (x, m), and whether a link
        other than a foot touches the ground, from the contacts of every physics step of the tick
        (``ids``, ``data``: the batch API's arbiter buffers, joined): the forces are the tick's mean,
        impulse / control_dt, as a force sensor low-passed at the tick sees them."""
        ids = np.frombuffer(ids, dtype=np.uintp).reshape(-1, 2)
        data = np.frombuffer(data).reshape(-1, 8)  # impulse x y, normal x y, point a x y, point b x y
        if len(ids) > 1:  # pymunk lists contacts in an order of memory addresses: sum them in an order of their values,
            order = np.lexsort(data.T)  # so that every run of a trial is the same to the last bit
            ids, data = ids[order], data[order]
        self._other_contact = False
        feet = self._state[FOOT_ROWS, :]  # x, y, angle of each foot's middle
        self._feet = np.column_stack([feet[:, 0], feet[:, 1], np.cos(feet[:, 2]), np.sin(feet[:, 2])])
        if not len(ids):
            self._forces = np.zeros(4)  # heel_l, toe_l, heel_r, toe_r
            self._foot_force = np.zeros(2)
            self._cop = float(0.5 * (self._state[4, 0] + self._state[7, 0]))  # stands in, airborne
            return
        right = (ids == self._foot_ids[1]).any(axis=1)
        on_foot = right | (ids == self._foot_ids[0]).any(axis=1)
        self._other_contact = not on_foot.all()
        right = right[on_foot]
        data = data[on_foot]
        normal = np.abs(data[:, 0] * data[:, 2] + data[:, 1] * data[:, 3]) / self.params.control_dt
        px = 0.5 * (data[:, 4] + data[:, 6])
        py = 0.5 * (data[:, 5] + data[:, 7])
        x, y, cos, sin = self._feet[right.astype(np.intp)].T  # each contact's foot: middle and axis
        toe = (px - x) * cos + (py - y) * sin > 0  # ahead of the foot's middle
        self._forces = forces = np.bincount(2 * right + toe, weights=normal, minlength=4)
        self._foot_force = forces[[0, 2]] + forces[[1, 3]]
        total = float(normal.sum())
        if total > 1e-9:
            self._cop = float(normal @ px) / total
        else:
            self._cop = float(0.5 * (self._state[4, 0] + self._state[7, 0]))

    # ------------------------------------------------------------------ sensing
    def _hip_x(self) -> float:
        x, y, angle = self._state[PELVIS_ROW, :3].tolist()
        return x + math.sin(angle) * PELVIS / 2  # the pelvis' bottom end: (0, -PELVIS/2) rotated

    def sense(self) -> np.ndarray:
        state = self._state
        com_x = float(_LINK_MASS @ state[:, 0]) / MASS
        pelvis_angle, pelvis_spin = state[PELVIS_ROW, 2:4].tolist()
        hip_x = self._hip_x()
        return np.concatenate(
            [
                self._angles,
                np.minimum(self._forces, MAX_FORCE),
                [
                    min(max(com_x - self._cop, -MAX_FALL), MAX_FALL),
                    -pelvis_angle,  # counter-clockwise = leaning back
                    min(max(-pelvis_spin, -MAX_SPEED), MAX_SPEED),
                    float(self.ground_slope(hip_x)),
                ],
                np.minimum(np.maximum(self._speeds, -MAX_SPEED), MAX_SPEED),
                [self._back],
            ]
        )

    # ------------------------------------------------------------------ acting
    def actuate(self, command: np.ndarray) -> None:
        p = self.params
        voltage = self.motor_voltage(command)
        dt, h = p.control_dt, p.control_dt / p.substeps
        # tau = k_t V / R per joint (+ = extension); the -k_t^2 omega / R part is the damper built in
        wrench = self._wrench
        wrench[self._rows, 2] = _TORQUE_MAP @ (voltage * (p.torque_constant / p.resistance))
        pushing = self.push_requested and self._push_start <= self.t + 1e-9 < self._push_end
        wrench[self._rows[TRUNK_ROW], 0] = self.push_force if pushing else 0.0
        if pushing:
            if self._push_first is None:
                self._push_first = self.t
            self._push_ticks += 1
        self.pushed = self.pushed or pushing
        self._back = max(self.push_force, 0.0) if pushing else 0.0  # a forward push presses on the back
        buffer = self._wrench_buffer
        space, set_bodies, fields = self.space, pymunk.batch.set_space_bodies, _BF.FORCE | _BF.TORQUE
        get_arbiters, contacts = pymunk.batch.get_space_arbiters, self._arbiter_buffer
        ids, data = [], []
        for _ in range(p.substeps):
            set_bodies(space, fields, buffer)  # pymunk zeroes forces and torques after every step
            space.step(h)
            contacts.clear()
            get_arbiters(space, _ARBITER_FIELDS, contacts)
            ids.append(bytes(contacts.int_buf()))
            data.append(bytes(contacts.float_buf()))
        self._read_state()
        self._read_contacts(b"".join(ids), b"".join(data))
        current = (voltage - p.torque_constant * self._speeds) / p.resistance
        self.energy += float(current @ current) * p.resistance * dt  # (5.5)-(5.6)
        self.t += dt
        self._count_steps()
        self._watch_gait()
        self._check_fall()
        if self._log is not None and self._tick % self._log_every == 0:
            self._log.append(
                np.concatenate([(self._tick,), self._state[:, :3].ravel(), self.sense(), voltage, (pushing,)])
            )
        self._tick += 1

    def motor_voltage(self, command: np.ndarray) -> np.ndarray:
        """The motors' voltages (V, COMMANDS order) for a tick's command: here the command itself, clipped."""
        return np.minimum(np.maximum(np.asarray(command, dtype=float), -MAX_VOLTAGE), MAX_VOLTAGE)

    def _watch_gait(self) -> None:
        """Left heel strikes (the heel force, the tick's mean, rising through ``heel_strike``; a rise within
        ``strike_refractory`` of the last strike is the same landing bouncing), and the push they place: with
        ``push_phase``, at the first strike at or after ``push_time`` by which T is measured, plus push_phase x T;
        with ``push_steps`` alone, at ``push_time``. T = the median interval of the strikes from ``gait_from`` on (at
        least MIN_GAIT_INTERVALS intervals); the push lasts push_steps x T / 2 (a step = half a cycle, §7.12)."""
        p = self.params
        on = bool(self._forces[0] >= p.heel_strike)
        struck = False
        if self._heel_on is False and on:  # the start's stance (no tick before) is no strike
            strikes = self.heel_strikes
            if not strikes or self.t - strikes[-1] > p.strike_refractory:
                strikes.append(self.t)
                struck = True
        self._heel_on = on
        if self._push_placed or self.t < self.push_time - 1e-9:
            return
        if self.push_phase is not None and not struck:
            return
        period = self._measured_period(self.t)
        if period is None:
            if self.push_phase is None:  # push_steps at push_time: no period measured by then, no push
                self._push_placed = True
            return
        onset = self.t if self.push_phase is None else self.t + self.push_phase * period
        if self.push_phase is not None:
            self.push_anchor = self.t
        if self.push_steps is not None:
            self.push_duration = self.push_steps * period / 2
        self.gait_period = period
        self._push_start, self._push_end = onset, onset + self.push_duration
        self._push_placed = True

    def _measured_period(self, until: float) -> float | None:
        """T (s): the median interval of the left heel strikes in [gait_from, until]; None with too few."""
        strikes = [t for t in self.heel_strikes if self.params.gait_from - 1e-9 <= t <= until + 1e-9]
        if len(strikes) < MIN_GAIT_INTERVALS + 1:
            return None
        return float(np.median(np.diff(strikes)))

    def _count_steps(self) -> None:
        p = self.params
        weight = MASS * G
        was = self._loaded
        loaded = np.where(was, self._foot_force > 0.5 * p.step_load * weight, self._foot_force > p.step_load * weight)
        for foot in (0, 1):
            if loaded[foot] and not was[foot] and foot != self._last_step_foot:
                ahead = self._state[FOOT_ROWS[foot], 0] > self._state[FOOT_ROWS[1 - foot], 0]
                if ahead:
                    self.steps += 1
                    self._last_step_foot = foot
        self._loaded = loaded

    def _check_fall(self) -> None:
        if self.fell:
            return
        x, y, angle = self._state[PELVIS_ROW, :3].tolist()
        hip_x, hip_y = x + math.sin(angle) * PELVIS / 2, y - math.cos(angle) * PELVIS / 2
        height = hip_y - float(self.ground_height(hip_x)) - GROUND_R
        reason = ""
        if height < self.params.fall_height * LEG:
            reason = f"hip {height:.2f} m above the ground"
        elif abs(angle) > math.radians(self.params.fall_tilt_deg):
            reason = f"pelvis tilted {math.degrees(-angle):.0f} deg"
        elif self._other_contact:
            reason = "a link other than a foot on the ground"
        if reason:
            self.fell, self.fell_at, self.fall_reason = True, self.t, reason

    @property
    def done(self) -> bool:
        return self.fell or self.t >= self.params.duration - 1e-9

    METRICS: ClassVar[dict[str, str]] = {
        "distance": "m",
        "velocity": "m/s",
        "steps": "",
        "time": "s",
        "energy": "J",
        "fell": "",
        "fell_at": "s",
        "pushed": "",
        "push_onset": "s",
        "push_duration": "s",
        "push_impulse": "N s",
        "push_anchor": "s",
        "gait_period": "s",
        "push_missed": "",
    }

    def outcome(self) -> tuple[bool, float, dict]:
        distance = self._hip_x() - self.x_start
        velocity = distance / self.t if self.t > 0 else 0.0
        success = (not self.fell) and self.steps >= self.params.min_steps  # E4.2, L1243
        # walking efficiency (5.7)-(5.8): kinetic energy at the mean speed over the electrical energy
        quality = walking_efficiency(MASS, velocity, self.energy) if success else 0.0
        metrics = {
            "distance": distance,
            "velocity": velocity,
            "steps": self.steps,
            "time": self.t,
            "energy": self.energy,
            "fell": self.fell,
            "fell_at": self.fell_at,
            "pushed": self.pushed,
        }
        if self.push_requested:  # unpushed trials keep the metrics above only
            onset, duration = self._push_first, self._push_ticks * self.params.control_dt
            period = self.gait_period
            if period is None and onset is not None:
                period = self._measured_period(onset)  # a push at a time: the gait before it
            metrics.update(
                {
                    "push_onset": onset,
                    "push_duration": duration,
                    "push_impulse": self.push_force * duration,
                    "push_anchor": self.push_anchor,
                    "gait_period": period,
                    "push_missed": not self.pushed,
                }
            )
        return success, quality, metrics

    # ------------------------------------------------------------------ recording
    def log_trial(self, trial_id: int) -> None:
        """A logged trial as telemetry on ``sim_time`` (trial k starts at k x duration): joint angles (deg),
        contact forces (N), the balance sensors and the motor voltages at ``rates.signals_hz``; the links
        as 2-D strips at ``rates.pictures_hz`` and the ground under their path; the push as arrows onto
        the trunk (1 m per 100 N) while it acts; the push and a fall as events."""
        if not self._log:
            return
        p, sink = self.params, self.telemetry
        rates = rates_of(sink)
        log = np.stack(self._log)
        ticks = log[:, 0].astype(np.int64)
        times = trial_id * p.duration + p.control_dt * (ticks + 1)  # the state after tick i
        poses = log[:, 1:25].reshape(-1, len(LINKS), 3)
        sensed = log[:, 25 : 25 + len(SENSORS)]
        voltage, pushing = log[:, 25 + len(SENSORS) : -1], log[:, -1] > 0.5
        shown = ticks % rates.signal_every(p.control_dt) == 0
        at = times[shown]
        for j, signal in enumerate(SENSORS[:_N_ANGLES]):
            sink.emit(series(f"joints/{signal.name}", trial_id, at, np.degrees(sensed[shown, j]), "deg"))
        for j, signal in enumerate(SENSORS[_N_ANGLES : _N_ANGLES + 4], start=_N_ANGLES):
            sink.emit(series(f"contacts/{signal.name}", trial_id, at, sensed[shown, j], "N"))
        sink.emit(series("balance/fall", trial_id, at, sensed[shown, _N_ANGLES + 4], "m"))
        sink.emit(series("balance/pelvis", trial_id, at, np.degrees(sensed[shown, _N_ANGLES + 5]), "deg"))
        for j, signal in enumerate(COMMANDS):  # motor voltages (3.6): the motor neurons' net output
            sink.emit(series(f"motors/{signal.name}", trial_id, at, voltage[shown, j], "V"))
        pictured = ticks % rates.picture_every(p.control_dt) == 0
        points = _picture_points(poses[pictured])
        strips = points[:, _STRIPS].reshape(-1, _STRIPS.shape[1], 2)  # (pictures x 6, 4, 2)
        sink.emit(Strips2D("walker", trial_id, times[pictured], strips, len(_STRIPS), _COLORS, follow=True))
        hip_x = points[:, 2, 0]
        gx = np.linspace(float(hip_x.min()) - 1.0, float(hip_x.max()) + 1.0, 80)
        ground = np.column_stack([gx, self.ground_height(gx) + GROUND_R])
        sink.emit(Strips2D("ground", trial_id, np.array([trial_id * p.duration]), [ground], 1, _GROUND_COLOR, 0.004))
        if self.pushed:
            rows = np.flatnonzero(pushing & pictured)
            if not len(rows):  # a push shorter than a picture's interval: one arrow at the next picture
                rows = np.flatnonzero(pictured & (times >= trial_id * p.duration + self._push_first))[:1]
            vectors = np.zeros((len(rows), 2))
            vectors[:, 0] = self.push_force / 100.0
            sink.emit(Arrows2D("push", trial_id, times[rows], poses[rows, TRUNK_ROW, :2] - vectors, vectors))
            text = f"push {self.push_force:g} N on the trunk for {self._push_ticks * p.control_dt:g} s"
            if self.push_anchor is not None:
                text += f", phase {self.push_phase:g} of the gait cycle T = {self.gait_period:.3f} s"
            sink.emit(Event("events/push", trial_id, trial_id * p.duration + self._push_first, text))
        if self.fell:
            text = f"fell: {self.fall_reason}"
            sink.emit(Event("events/fall", trial_id, trial_id * p.duration + self.fell_at, text, "WARN"))

    def close(self) -> None:
        self.space = None


def _picture_points(poses: np.ndarray) -> np.ndarray:
    """(frames, 11, 2) picture points from the links' (frames, 8, 3) x, y, angle (LINKS order): trunk top,
    trunk joint, hip, left knee, left ankle, left heel, left toe, right knee, right ankle, right heel,
    right toe (a link's point (lx, ly) in its own frame is at (x + lx cos a - ly sin a, y + lx sin a + ly cos a))."""
    x, y, a = poses[:, _PICTURE_LINKS, 0], poses[:, _PICTURE_LINKS, 1], poses[:, _PICTURE_LINKS, 2]
    lx, ly = _PICTURE_LOCAL.T
    c, s = np.cos(a), np.sin(a)
    return np.stack([x + c * lx - s * ly, y + s * lx + c * ly], axis=-1)


# --- the position-servo variant ------------------------------------------------------------------------------------
SERVO_GAIN = 30.0  # V/rad: K_p, see PlanarWalker8Servo
SERVO_DAMPING = 0.0  # V s/rad: K_d, see PlanarWalker8Servo
_LOW = np.array([j[4][0] for j in JOINTS])
_HIGH = np.array([j[4][1] for j in JOINTS])
SERVO_COMMANDS = tuple(
    Signal(f"q_{j[0]}", "rad", *j[4], f"{j[0]} position target, + = extension, clipped to its stops") for j in JOINTS
)


class PlanarWalker8ServoParams(PlanarWalker8Params):
    strike_refractory: float = Field(
        0.6,
        ge=0,
        le=5,
        description="s: a heel force rising again within this of the last strike is the same landing (0.6 here: "
        "this walker's heel can land twice in a cycle, about 0.5 s apart)",
    )
    servo_gain: float = Field(
        SERVO_GAIN, gt=0, le=150, description="K_p: V per rad of position error (the servo's proportional gain)"
    )
    servo_damping: float = Field(
        SERVO_DAMPING,
        ge=0,
        lt=1.5,
        description="K_d: V per rad/s of joint speed, on top of the motor's own back-EMF (below k_t = 1.5: stable "
        "at the 10-ms tick)",
    )


class PlanarWalker8Servo(PlanarWalker8):
    """The 8-link walker with a position servo per joint (L1201): commands are target angles ``q_<joint>`` (rad), the
    servo drives the voltage walker's DC motors (see the module docstring)."""

    Params = PlanarWalker8ServoParams
    COMMANDS = SERVO_COMMANDS

    def motor_voltage(self, command: np.ndarray) -> np.ndarray:
        """The servo: V = clip(K_p (q_cmd - q) - K_d omega, +-MAX_VOLTAGE), q_cmd clipped to the joint's stops, q and
        omega the joint's angle and speed at the start of the tick, into the same DC motor as the voltage walker."""
        p = self.params
        target = np.minimum(np.maximum(np.asarray(command, dtype=float), _LOW), _HIGH)
        voltage = p.servo_gain * (target - self._angles) - p.servo_damping * self._speeds
        return np.minimum(np.maximum(voltage, -MAX_VOLTAGE), MAX_VOLTAGE)
