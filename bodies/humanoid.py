"""A NAO-sized humanoid in PyBullet (thesis chapters 4-5; issue 16), built from boxes.

The body is the NAO V4.0 of ``humanoid_table.py`` (one table of numbers: kinematics, masses, joint
limits, efforts, speeds, motors; sources there and in CPG-HUMANOID.md §6): a torso with the head,
two arms on their shoulder pitch, and two legs with hip roll, hip pitch, knee, ankle pitch and
ankle roll (HipYawPitch fixed at 0), the twelve joints of the thesis's CPG (L1339). The URDF is
generated from the table into a cache file; every NAO link is a solid box at its centre of mass.

**Joints.** Angles and commands are NAO's (rad, Aldebaran signs; 0 = legs straight, arms forward):
pitch joints turn about +y (hip pitch and ankle pitch +: extension, knee +: flexion, shoulder +:
arm down), roll joints about +x (+: the left leg out, the right leg in). Each joint is a position
servo, like NAO's motor boards: every physics step its speed target is ``servo_rate * (q_cmd - q)``,
clipped to the joint's published speed, reached with a torque of at most ``servo_stiffness * |q_cmd - q|``
(a P controller's; chosen here so that two feet on the ground cannot make the servos fight at full
effort), never more than the published effort (§6). The motor torques are read back every physics
step for the energy model.

**Sensors.** Joint angles, velocities and motor torques; four pressure sensors (FSR) per foot at
NAO's places (§6: toe/heel x = +0.070/-0.030 m, inner/outer y = 0.023/0.030 m), each contact force on
the sole shared among them bilinearly, so the four add up to the foot's normal force; ``heel_*`` and
``toe_*`` are the sums of the heel and toe pairs, the inputs of GB and GF (L1345); the torso's pitch
and roll from an IMU model (NAO's inertial board reports the fused attitude: here the exact one,
noise-free) and its body-frame rates, and ``back``: the forward force pressing the robot over the last tick (N; a
touch sensor, chosen here: a push or the ball; a controller's perfect push detector, E4.7). ``torso_pitch`` is the
torso's angle to the vertical in its sagittal plane, + = leaning forward, the input of FB/FF (L1347); ``torso_roll`` +
= leaning right (about +x). Every value saturates at its declared bounds.

**Energy and efficiency** (5.4)-(5.8): P = sum_i c_i tau_i^2 with c_i = omega_0 / (tau_stall N_i^2)
(§6, eta_g = 1), E_e = integral of P dt from the start to the finish line, E_k = m v_a^2 / 2 with
v_a = 1.5 m / that time, eta = E_k / E_e for a success, 0 for a failure.

**Trial.** The torso starts at x = 0, standing (``STANDING``, its ankles pitched by the slope so the
soles lie on the ground, the torso upright). Success: the torso's centre of mass crosses
``finish_line`` (1.5 m, L1650). Failure: a fall (the torso's centre of mass below
``fall_height_fraction`` of its starting height above the ground, or |pitch| or |roll| over
``fall_angle_deg``), leaving the lane (|y| > ``lane_half_width``) or the time-out (``duration``).

**Conditions** (trial parameters): ``slope_deg`` (a constant ramp, uphill +, within +-15 deg),
``terrain`` (pieces ``length:slope_deg`` from x = 0, e.g. ``"1.0:0,3.0:10"`` for flat then uphill), and a
push on the torso: ``push_force`` N for ``push_duration`` s from ``push_time`` s, horizontal, toward
``push_direction_deg`` (0 = forward, from behind; 90 = toward +y). E4.7's ball (L1430) is its push:
34 N for 0.1 s from behind at t = 9 s. Or a real ball: ``ball_mass`` kg (> 0: there is one) thrown at
``ball_speed`` m/s at ``ball_time`` s from ``BALL_GAP`` m behind the torso, its centre ``ball_height`` m above
the torso's centre of mass (aimed so that gravity brings it back to that height on arrival); what it delivers
is measured (metrics ``ball_impulse`` N s and ``ball_peak_force`` N: the forward component of its contact forces
on the robot, summed over the ``BALL_WATCH`` s after the throw). ``start_noise`` (rad) sets a trial's own start
perturbation (the parameter's value otherwise).

**Speed.** One PyBullet client per body (DIRECT, no GUI). A world is built once per terrain and saved;
the next trial on that terrain restores it (``restoreState``), which gives the same trial bit for bit
as a fresh build (tests/bodies/test_humanoid.py). Solver settings: docs/bodies/humanoid.md.
"""

from __future__ import annotations

import hashlib
import math
import os
import tempfile
from typing import ClassVar, Literal

import numpy as np
from pydantic import Field, field_validator, model_validator

from sfl_brain.bodies.humanoid_table import (
    FSR_X,
    FSR_Y,
    JOINTS,
    LINKS,
    PARTS,
    SOLE,
    STANDING,
    TOTAL_MASS,
    motor_coefficient,
)
from sfl_brain.bodies.planar_biped import TERRAIN_SYNTAX, parse_terrain
from sfl_brain.body import Body, BodyParams, check_number, walking_efficiency
from sfl_brain.messages import TrialRequest
from sfl_brain.signals import Signal
from sfl_brain.telemetry import Arrows2D, Boxes3D, Event, rates_of, series


def _import_pybullet_quietly():
    """pybullet prints its build time when first imported (from C, on standard error in 3.2.7, so ``sys.stderr``
    cannot catch it); it would land in ``sfl list`` and ``sfl check`` output. Both descriptors are muted for the
    import only (an import error still raises, with its message)."""
    import sys

    if "pybullet" in sys.modules:
        return sys.modules["pybullet"]
    sys.stdout.flush()
    sys.stderr.flush()
    saved = {fd: os.dup(fd) for fd in (1, 2)}
    try:
        with open(os.devnull, "w") as null:
            for fd in saved:
                os.dup2(null.fileno(), fd)
            import pybullet
    finally:
        for fd, copy in saved.items():
            os.dup2(copy, fd)
            os.close(copy)
    return pybullet


pb = _import_pybullet_quietly()

G = 9.81  # m/s^2
MAX_SLOPE_DEG = 15.0  # the steepest ramp a trial may ask for (issue 16; the thesis's are 10 and 11 deg)
MAX_PUSH = 200.0  # N: the hardest push a trial may ask for (chosen here: ~4 body weights)
MAX_JOINT_SPEED = 25.0  # rad/s: velocity sensor range (chosen here: 3 x the fastest no-load joint speed, 8.3)
MAX_FSR = 100.0  # N per pressure sensor (chosen here: 2 body weights; reached only in impacts)
MAX_GYRO = 20.0  # rad/s: gyro range (chosen here)
MAX_BACK = 1000.0  # N: the touch sensor `back` saturates here
GROUND_THICKNESS = 0.2  # m
CLEARANCE = 0.0005  # m between the soles and the ground at the start
HOLD_TORQUE = 0.05  # N m: what a servo resists with at zero error (chosen here: about NAO's joint friction)

JOINT_NAMES = tuple(j.name for j in JOINTS)
LOWER = np.array([j.lower for j in JOINTS])
UPPER = np.array([j.upper for j in JOINTS])
EFFORT = np.array([j.effort for j in JOINTS])
SPEED = np.array([j.velocity for j in JOINTS])
MOTOR = np.array([motor_coefficient(j) for j in JOINTS])  # c_i of P = c_i tau_i^2, W / (N m)^2
_SPEED, _EFFORT = SPEED.tolist(), EFFORT.tolist()  # the same, as floats for the servo loop (actuate)
FEET = ("foot_l", "foot_r")
FSR_NAMES = tuple(f"fsr_{side}_{end}_{edge}" for side in "lr" for end in ("toe", "heel") for edge in ("inner", "outer"))

SENSORS = (
    *(Signal(j.name, "rad", j.lower, j.upper, f"{j.nao} angle, + = {j.plus}") for j in JOINTS),
    *(
        Signal(f"{j.name}_velocity", "rad/s", -MAX_JOINT_SPEED, MAX_JOINT_SPEED, f"{j.nao} angular velocity")
        for j in JOINTS
    ),
    *(
        Signal(f"{j.name}_torque", "N m", -j.effort, j.effort, f"{j.nao} motor torque (last physics step)")
        for j in JOINTS
    ),
    Signal("heel_l", "N", 0.0, 2 * MAX_FSR, "left heel: sum of its two pressure sensors (GB's input, L1345)"),
    Signal("toe_l", "N", 0.0, 2 * MAX_FSR, "left toe: sum of its two pressure sensors (GF's input)"),
    Signal("heel_r", "N", 0.0, 2 * MAX_FSR, "right heel pressure sensors, summed"),
    Signal("toe_r", "N", 0.0, 2 * MAX_FSR, "right toe pressure sensors, summed"),
    *(Signal(name, "N", 0.0, MAX_FSR, "one foot pressure sensor (FSR), normal force") for name in FSR_NAMES),
    Signal("torso_pitch", "rad", -math.pi, math.pi, "torso angle to the vertical, + = leaning forward (L1347)"),
    Signal("torso_roll", "rad", -math.pi, math.pi, "torso angle to the vertical, + = leaning right (about +x)"),
    Signal("torso_pitch_rate", "rad/s", -MAX_GYRO, MAX_GYRO, "gyro: torso rate about its own y axis"),
    Signal("torso_roll_rate", "rad/s", -MAX_GYRO, MAX_GYRO, "gyro: torso rate about its own x axis"),
    Signal(
        "back", "N", 0.0, 1000.0, "forward force pressing the robot over the last tick (a touch sensor: a push, a ball)"
    ),
)
COMMANDS = tuple(
    Signal(f"q_{j.name}", "rad", j.lower, j.upper, f"{j.nao} position target, clipped to its limits") for j in JOINTS
)
SENSOR_LOW = np.array([s.low for s in SENSORS])
SENSOR_HIGH = np.array([s.high for s in SENSORS])
N = len(JOINTS)


# ---------------------------------------------------------------------------------------------------- model
def _box_inertia(mass: float, size) -> np.ndarray:
    x, y, z = size
    return np.diag([y * y + z * z, x * x + z * z, x * x + y * y]) * mass / 12


def link_inertial(link: str) -> tuple[float, np.ndarray, np.ndarray]:
    """(mass kg, centre of mass m, inertia tensor about it kg m^2) of a simulated link: its parts' boxes,
    moved to the common centre of mass (parallel axes)."""
    parts = [p for p in PARTS if p.link == link]
    mass = sum(p.mass for p in parts)
    com = sum(p.mass * np.array(p.com) for p in parts) / mass
    inertia = np.zeros((3, 3))
    for p in parts:
        d = np.array(p.com) - com
        inertia += _box_inertia(p.mass, p.size) + p.mass * (d @ d * np.eye(3) - np.outer(d, d))
    return mass, com, inertia


def urdf_text(mass_scale: float = 1.0) -> str:
    """The humanoid's URDF, generated from the table (collision boxes only: DIRECT mode draws nothing); every link's
    mass and inertia times ``mass_scale`` (1: the table's; the same shapes and centres of mass)."""
    xyz = " ".join  # a URDF triple
    out = ['<?xml version="1.0"?>', '<robot name="nao_v40_boxes">']
    for link in LINKS:
        mass, com, i = link_inertial(link)
        if mass_scale != 1.0:
            mass, i = mass * mass_scale, i * mass_scale
        out.append(f'  <link name="{link}">')
        out.append(
            f'    <inertial><origin xyz="{xyz(map(repr, com.tolist()))}"/><mass value="{mass!r}"/>'
            f'<inertia ixx="{i[0, 0]!r}" ixy="{i[0, 1]!r}" ixz="{i[0, 2]!r}" iyy="{i[1, 1]!r}" iyz="{i[1, 2]!r}" '
            f'izz="{i[2, 2]!r}"/></inertial>'
        )
        for p in PARTS:
            if p.link == link and p.collides:
                out.append(
                    f'    <collision name="{p.name}"><origin xyz="{xyz(map(repr, p.com))}"/>'
                    f'<geometry><box size="{xyz(map(repr, p.size))}"/></geometry></collision>'
                )
        out.append("  </link>")
    for j in JOINTS:
        out.append(
            f'  <joint name="{j.name}" type="revolute"><parent link="{j.parent}"/><child link="{j.child}"/>'
            f'<origin xyz="{xyz(map(repr, j.origin))}"/><axis xyz="{xyz(map(repr, j.axis))}"/>'
            f'<limit lower="{j.lower!r}" upper="{j.upper!r}" effort="{j.effort!r}" velocity="{j.velocity!r}"/></joint>'
        )
    out.append("</robot>")
    return "\n".join(out) + "\n"


def urdf_path(mass_scale: float = 1.0) -> str:
    """The generated URDF in the temp directory, named by its content's hash (written once, atomically)."""
    text = urdf_text(mass_scale)
    path = os.path.join(tempfile.gettempdir(), f"sfl_humanoid_{hashlib.sha1(text.encode()).hexdigest()[:12]}.urdf")
    if not os.path.exists(path):
        fd, tmp = tempfile.mkstemp(suffix=".urdf", dir=os.path.dirname(path))
        with os.fdopen(fd, "w") as f:
            f.write(text)
        os.replace(tmp, path)
    return path


def _rotate(quaternions: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """Vectors (n, 3) turned by unit quaternions (n, 4) in PyBullet's (x, y, z, w) order."""
    u, w = quaternions[:, :3], quaternions[:, 3:]
    t = 2 * np.cross(u, vectors)
    return vectors + w * t + np.cross(u, t)


# ---------------------------------------------------------------------------------------------------- checks
def _slope(value, where: str = "") -> float:
    where = f"{where}: " if where else ""
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ValueError(f"{where}expected a number of degrees; got {value!r}")
    if abs(value) > MAX_SLOPE_DEG:
        raise ValueError(f"{where}expected a slope within +-{MAX_SLOPE_DEG:g} deg; got {value!r}")
    return float(value)


PUSH_RANGES = {
    "push_force": (0.0, MAX_PUSH),  # N
    "push_time": (0.0, 600.0),  # s
    "push_duration": (0.0, 10.0),  # s
    "push_direction_deg": (-180.0, 180.0),  # deg, 0 = forward
    "ball_mass": (0.0, 10.0),  # kg (0: no ball)
    "ball_speed": (0.0, 30.0),  # m/s, forward
    "ball_time": (0.0, 600.0),  # s: when it is thrown
    "ball_height": (-0.3, 0.3),  # m: its centre above the torso's centre of mass
}
START_RANGES = {"start_noise": (0.0, 0.2)}  # rad: a trial's own start_noise (the parameter's range)
BALL_RADIUS = 0.05  # m: chosen here (the thesis gives the ball's force, not the ball)
BALL_GAP = 0.15  # m: from the ball's centre to the torso's centre of mass when thrown (it arrives in about gap / speed)
BALL_WATCH = 0.2  # s after the throw during which its contacts with the robot are summed (the hit, not a ball at rest)


class HumanoidParams(BodyParams):
    duration: float = Field(60.0, gt=0, le=600, description="trial time-out, s of simulated time (digest §7.14)")
    substeps: int = Field(4, ge=1, le=40, description="physics steps per control tick (4: 400 Hz at 10 ms)")
    solver_iterations: int = Field(10, ge=1, le=200, description="PyBullet constraint solver iterations")
    friction: float = Field(0.8, gt=0, le=2, description="sole-ground friction coefficient")
    servo_rate: float = Field(20.0, gt=0, le=1000, description="1/s: joint speed target per rad of position error")
    servo_stiffness: float = Field(100.0, gt=0, description="N m/rad: a servo's torque is at most this x its error")
    slope_deg: float = Field(0.0, ge=-MAX_SLOPE_DEG, le=MAX_SLOPE_DEG, description="deg: ramp if a trial sets none")
    finish_line: float = Field(1.5, gt=0, description="m: the torso crossing x = this is a success (L1650)")
    lane_half_width: float = Field(0.5, gt=0, description="m: |y| of the torso beyond this is a failure")
    fall_height_fraction: float = Field(0.5, gt=0, lt=1, description="fall: torso CoM below this x its start height")
    fall_angle_deg: float = Field(45.0, gt=0, le=180, description="fall: |torso pitch| or |roll| over this, deg")
    start_noise: float = Field(0.0, ge=0, le=0.2, description="rad: s.d. of the start's joint offsets (trial seed)")
    run_up: float = Field(1.0, gt=0, le=100, description="m of ground behind the start, along the first piece")
    run_out: float = Field(20.0, gt=0, le=1000, description="m of ground after the last piece")
    ground_width: float = Field(2.0, gt=0, le=1000, description="m: the ground's width (the lane is +-0.5 m)")
    total_mass: float | None = Field(
        None,
        gt=1.0,
        le=20.0,
        description="kg: every link's mass (and inertia) scaled so that the robot weighs this; none: the table's "
        f"{TOTAL_MASS:.3f} kg (NAO V4.0). The thesis's robot weighs 4.3 kg (L1430; issue 29's E4.7 at 4.3 kg)",
    )
    physics: Literal["pybullet", "mujoco"] = Field("pybullet", description="physics engine (mujoco: an extra, 31)")

    @field_validator("physics")
    @classmethod
    def _engine_installed(cls, physics: str) -> str:  # MuJoCo is optional: refused at `sfl check` without it
        if physics == "mujoco":
            from sfl_brain.bodies.humanoid_mujoco import import_mujoco

            try:
                import_mujoco()
            except ImportError as exc:
                raise ValueError(str(exc)) from None
        return physics

    @model_validator(mode="after")
    def _mass_on_pybullet(self) -> HumanoidParams:  # the MJCF has the table's masses only (issue 31)
        if self.physics == "mujoco" and self.total_mass is not None:
            raise ValueError("total_mass is PyBullet's only for now: with physics: mujoco leave it out (none)")
        return self


class Humanoid(Body):
    """NAO V4.0-sized humanoid (PyBullet, boxes): 12 position servos, foot pressure, IMU, motor energy."""

    Params = HumanoidParams
    SENSORS = SENSORS
    COMMANDS = COMMANDS
    TRIAL_PARAMS = ("slope_deg", "terrain", *PUSH_RANGES, *START_RANGES)
    LAYOUT = "humanoid"  # the recording's default layout: the walk in 3-D, the torso pitch with the terrain switch

    def __new__(cls, params: HumanoidParams | None = None, *, seed: int = 0):
        if params is not None and params.physics == "mujoco":  # the same body on MuJoCo (humanoid_mujoco.py)
            from sfl_brain.bodies.humanoid_mujoco import HumanoidMujoco

            return HumanoidMujoco.__new__(HumanoidMujoco, params, seed=seed)
        return super().__new__(cls)

    def __init__(self, params: HumanoidParams | None = None, *, seed: int = 0) -> None:
        super().__init__(params, seed=seed)
        total = self.params.total_mass
        self.mass_scale = 1.0 if total is None else total / TOTAL_MASS  # every link's mass x this
        self.mass = TOTAL_MASS * self.mass_scale  # kg: m of (5.7)
        self._next_piece: float | None = None  # x (m) where the ground changes first (a trial's terrain)
        self.terrain_reached = -1.0
        self.client: int | None = None  # PyBullet's, made by the first trial
        self._world_key = None  # (terrain, ball or not) of the world built and saved
        self._saved: int | None = None
        self.ball: int | None = None  # the ball's body, in worlds built for a ball

    # ------------------------------------------------------------------ conditions
    @classmethod
    def check_trial_param(cls, name: str, value) -> None:
        """Raise ValueError if ``value`` cannot be trial parameter ``name`` (``sfl check`` calls this)."""
        if name == "slope_deg":
            _slope(value)
        elif name == "terrain":
            for k, (_, slope) in enumerate(parse_terrain(value)):
                _slope(slope, f"piece {k} of terrain {value!r}")
        elif name in PUSH_RANGES:
            check_number(name, value, *PUSH_RANGES[name])
        elif name in START_RANGES:
            check_number(name, value, *START_RANGES[name])

    def _pieces(self, body_params: dict) -> tuple[tuple[float, float], ...]:
        """(length m, slope rad) pieces of the ground from x = 0."""
        profile = body_params.get("terrain")
        if profile:
            pieces = parse_terrain(profile)
            for k, (_, slope) in enumerate(pieces):
                _slope(slope, f"piece {k} of terrain {profile!r} ({TERRAIN_SYNTAX})")
            return tuple((length, math.radians(slope)) for length, slope in pieces)
        return ((1.0, math.radians(_slope(body_params.get("slope_deg", self.params.slope_deg), "slope_deg"))),)

    # ------------------------------------------------------------------ world
    def start_trial(self, request: TrialRequest) -> None:
        p = self.params
        body_params = request.body_params
        pieces = self._trial_conditions(body_params)
        if self.client is None:
            self.client = pb.connect(pb.DIRECT)
        # a world with a ball is another world: trials without one keep theirs, bit for bit
        key = (pieces, self.ball_mass > 0)
        if key != self._world_key:
            self._build(pieces, ball=self.ball_mass > 0)
        else:
            # the contact cache is not part of a saved state: lift the robot clear and let collision detection
            # drop its contact points, so that no trial inherits the last one's (then restore the start)
            pb.resetBasePositionAndOrientation(self.robot, (0.0, 0.0, 100.0), (0, 0, 0, 1), physicsClientId=self.client)
            pb.performCollisionDetection(physicsClientId=self.client)
            pb.restoreState(self._saved, physicsClientId=self.client)
        start_noise = float(body_params.get("start_noise", p.start_noise))  # a trial may set its own
        if start_noise > 0:
            offsets = np.random.default_rng(request.seed).normal(0.0, start_noise, N)
            start = np.clip(self._start_pose + offsets, LOWER, UPPER)
            for i, angle in zip(self.joint_index, start.tolist(), strict=True):
                pb.resetJointState(self.robot, i, angle, 0.0, physicsClientId=self.client)
        self._begin_trial()
        if self.ball is not None:
            pb.changeDynamics(self.ball, -1, mass=self.ball_mass, physicsClientId=self.client)

    def _trial_conditions(self, body_params: dict) -> tuple[tuple[float, float], ...]:
        """A trial's conditions from its parameters (each checked): the push, the ball, the terrain's pieces (returned)
        and where the ground changes first. Shared by both engines."""
        for name in (*PUSH_RANGES, *START_RANGES):
            if name in body_params:
                self.check_trial_param(name, body_params[name])
        self.push_force = float(body_params.get("push_force", 0.0))
        self.push_start = float(body_params.get("push_time", 0.0))
        self.push_end = self.push_start + float(body_params.get("push_duration", 0.0))
        direction = math.radians(float(body_params.get("push_direction_deg", 0.0)))
        self.push_vector = self.push_force * np.array([math.cos(direction), math.sin(direction), 0.0])
        self.ball_mass = float(body_params.get("ball_mass", 0.0))
        self.ball_speed = float(body_params.get("ball_speed", 0.0))
        self.ball_time = float(body_params.get("ball_time", 0.0))
        self.ball_height = float(body_params.get("ball_height", 0.0))
        self.ball_impulse = self.ball_peak = 0.0
        self._ball_thrown = False
        pieces = self._pieces(body_params)
        # where the ground changes first (x, m), watched for the metric terrain_reached: None on one piece of ground
        self._next_piece = pieces[0][0] * math.cos(pieces[0][1]) if len(pieces) > 1 else None
        self._next_slope = math.degrees(pieces[1][1]) if len(pieces) > 1 else None
        self.terrain_reached = -1.0  # s: when a foot first touched the next piece of ground (-1: not yet, or none)
        return pieces

    def _begin_trial(self) -> None:
        """The trial's clock, energy, judging state and logging buffers, and its first reads, once the start is set.
        Shared by both engines."""
        p = self.params
        self.ticks, self.t = 0, 0.0
        self.back = 0.0  # N: the touch sensor `back` (see actuate)
        self.energy = 0.0  # E_e (5.6), J
        self.fell = self.left_lane = self.finished = False
        self.finish_time = math.nan
        self._start_joints()
        self._read_torso()
        # a logged trial keeps samples of its signals and pictures of the body at the sink's rates
        rates = rates_of(self.telemetry)
        self._signal_every = rates.signal_every(p.control_dt)
        self._picture_every = rates.picture_every(p.control_dt)
        self._trace = [] if self.logging else None  # (t, sensor values, motor power W, (x, y, heading))
        self._frames = [] if self.logging else None  # (t, link poses, feet's centre of pressure and force)
        self._pushes = [] if self.logging else None  # (t, torso centre of mass, force) every physics step of a push

    def _build(self, pieces: tuple[tuple[float, float], ...], ball: bool = False) -> None:
        """A new world: the ground of ``pieces``, the robot standing at x = 0 on it, and (``ball``) a ball resting on
        the run-up, off the lane; saved for the next trials."""
        p, c = self.params, self.client
        if self._saved is not None:
            pb.removeState(self._saved, physicsClientId=c)
        pb.resetSimulation(physicsClientId=c)
        pb.setPhysicsEngineParameter(
            fixedTimeStep=p.control_dt / p.substeps,
            numSolverIterations=p.solver_iterations,
            deterministicOverlappingPairs=1,
            physicsClientId=c,
        )
        pb.setGravity(0.0, 0.0, -G, physicsClientId=c)
        self._build_ground(pieces)
        self.robot = pb.loadURDF(urdf_path(self.mass_scale), flags=pb.URDF_USE_INERTIA_FROM_FILE, physicsClientId=c)
        names = {pb.getJointInfo(self.robot, i, physicsClientId=c)[1].decode(): i for i in range(N)}
        self.joint_index = [names[name] for name in JOINT_NAMES]
        self.link_index = {"torso": -1} | {j.child: names[j.name] for j in JOINTS}  # a link's index = its joint's
        self.foot_index = [self.link_index[foot] for foot in FEET]
        self._picture_links = [self.link_index[link] for link in LINKS[1:]]  # the pictures' order
        for link in self.link_index.values():  # friction is the product of both sides': the ground's sets it
            pb.changeDynamics(self.robot, link, lateralFriction=1.0, physicsClientId=c)
        # the base's inertial frame (centre of mass, principal axes) relative to the torso's own frame
        info = pb.getDynamicsInfo(self.robot, -1, physicsClientId=c)
        self._inertial = (info[3], info[4])
        self._to_link = pb.invertTransform(*self._inertial)
        self._place(pieces[0][1])
        self.ball = None
        if ball:
            shape = pb.createCollisionShape(pb.GEOM_SPHERE, radius=BALL_RADIUS, physicsClientId=c)
            x = -p.run_up + 2 * BALL_RADIUS  # parked: on the run-up, far behind the robot
            z = self.ground_height(x) + BALL_RADIUS
            self.ball = pb.createMultiBody(1.0, shape, -1, (x, 0.0, z), physicsClientId=c)
            pb.changeDynamics(self.ball, -1, restitution=0.0, lateralFriction=0.5, physicsClientId=c)
        self._world_key = (pieces, ball)
        self._saved = pb.saveState(physicsClientId=c)

    def _build_ground(self, pieces) -> None:
        """Static boxes whose top faces follow the profile: the pieces, the first one extended back by a
        run-up, the last one forward by a run-out."""
        c, p = self.client, self.params
        lengths = [length for length, _ in pieces]
        lengths[0] += p.run_up  # the run-up is part of the first piece: no seam under the start
        lengths[-1] += p.run_out
        first = pieces[0][1]
        points = [(-p.run_up * math.cos(first), -p.run_up * math.sin(first))]
        for length, (_, slope) in zip(lengths, pieces, strict=True):
            x, z = points[-1]
            points.append((x + length * math.cos(slope), z + length * math.sin(slope)))
        self.ground_x, self.ground_z = np.array(points).T
        self.ground_boxes = []  # (centre, half sizes, quaternion) for the pictures
        for (x0, z0), (x1, z1) in zip(points[:-1], points[1:], strict=True):
            length, slope = math.hypot(x1 - x0, z1 - z0), math.atan2(z1 - z0, x1 - x0)
            half = (length / 2, p.ground_width / 2, GROUND_THICKNESS / 2)
            centre = ((x0 + x1) / 2 + math.sin(slope) * half[2], 0.0, (z0 + z1) / 2 - math.cos(slope) * half[2])
            turn = pb.getQuaternionFromEuler((0.0, -slope, 0.0))
            shape = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=half, physicsClientId=c)
            ground = pb.createMultiBody(0.0, shape, -1, centre, turn, physicsClientId=c)
            pb.changeDynamics(ground, -1, lateralFriction=p.friction, physicsClientId=c)
            self.ground_boxes.append((centre, half, turn))

    def ground_height(self, x: float) -> float:
        return float(np.interp(x, self.ground_x, self.ground_z))

    def _place(self, slope: float) -> None:
        """Stand the robot at x = 0: the standing pose with the ankles pitched by ``slope`` (soles on the
        ground), the torso as upright as the pose makes it, its centre of mass at x = 0, soles just above."""
        c, robot = self.client, self.robot
        pose = np.array([STANDING[name] for name in JOINT_NAMES])
        pose[[JOINT_NAMES.index("ankle_pitch_l"), JOINT_NAMES.index("ankle_pitch_r")]] -= slope
        self._start_pose = pose
        # feet flat: the torso's pitch cancels the legs' pitch sum (hip + knee + ankle, all about y)
        lean = -(STANDING["hip_pitch_l"] + STANDING["knee_l"] + STANDING["ankle_pitch_l"])
        for i, angle in zip(self.joint_index, pose.tolist(), strict=True):
            pb.resetJointState(self.robot, i, angle, 0.0, physicsClientId=c)
        self._set_torso((0.0, 0.0, 1.0), pb.getQuaternionFromEuler((0.0, lean, 0.0)))
        com = pb.getBasePositionAndOrientation(robot, physicsClientId=c)[0]
        lowest = math.inf
        states = pb.getLinkStates(robot, self.foot_index, computeForwardKinematics=1, physicsClientId=c)
        for foot, state in zip(FEET, states, strict=True):
            sole = next(part for part in PARTS if part.link == foot and part.collides)
            corners = [
                (sole.com[0] + dx * sole.size[0] / 2, sole.com[1] + dy * sole.size[1] / 2, -SOLE)
                for dx in (-1, 1)
                for dy in (-1, 1)
            ]
            position, turn = np.array(state[4]), np.tile(state[5], (4, 1))
            world = position + _rotate(turn, np.array(corners))
            gaps = world[:, 2] - np.interp(world[:, 0] - com[0], self.ground_x, self.ground_z)
            lowest = min(lowest, float(gaps.min()))
        base = pb.getBasePositionAndOrientation(robot, physicsClientId=c)
        shifted = (base[0][0] - com[0], base[0][1], base[0][2] - lowest + CLEARANCE)
        pb.resetBasePositionAndOrientation(robot, shifted, base[1], physicsClientId=c)
        self._read_torso()
        self.start_height = self.torso_position[2] - self.ground_height(self.torso_position[0])

    def _set_torso(self, position, orientation) -> None:
        """Put the torso's own frame (not its centre of mass) at this pose."""
        com = pb.multiplyTransforms(position, orientation, *self._inertial)
        pb.resetBasePositionAndOrientation(self.robot, *com, physicsClientId=self.client)

    # ------------------------------------------------------------------ sensing
    def _read_joints(self) -> None:
        states = pb.getJointStates(self.robot, self.joint_index, physicsClientId=self.client)
        q, dq, _, tau = (list(column) for column in zip(*states, strict=True))
        self.q, self.dq, self.tau = np.array(q), np.array(dq), np.array(tau)
        self._joint_lists = (q, dq, tau)  # the same as plain floats, for sense

    def _start_joints(self) -> None:
        """The joints at a trial's start: their angles and velocities as set, and no torque, since no motor has
        acted yet (PyBullet's joint state still holds the last trial's last applied torque, which the first frame
        would report: a trial's start would depend on the trial before it, issue 32)."""
        self._read_joints()
        q, dq, _ = self._joint_lists
        self.tau = np.zeros(N)
        self._joint_lists = (q, dq, [0.0] * N)

    def _read_torso(self) -> None:
        """The torso's centre of mass, its own frame's rotation matrix, and its spin in that frame."""
        c = self.client
        position, orientation = pb.getBasePositionAndOrientation(self.robot, physicsClientId=c)
        spin = pb.getBaseVelocity(self.robot, physicsClientId=c)[1]
        turn = pb.multiplyTransforms((0, 0, 0), orientation, *self._to_link)[1]
        self.torso_position = position
        self.torso_turn = np.array(pb.getMatrixFromQuaternion(turn)).reshape(3, 3)
        self.torso_spin = self.torso_turn.T @ spin  # gyro: body frame

    def _foot_pressure(self) -> list[float]:
        """The 8 FSR forces (N, FSR_NAMES order): each sole contact's normal force shared bilinearly between
        the toe and heel rows and the inner and outer columns of its foot's sensors (the shares add up to
        the force; a contact beyond a row or column counts as on it). Plain floats: a foot has few contacts.

        The robot's contact points and both feet's frames are asked for once each; the points are shared out by link:
        the same points in the same order as asking per foot (PyBullet filters its one list of points either way;
        tests/bodies/test_humanoid_speed.py). Each clip to [0, 1] is written as
        ``min(max(share, 0.0), 1.0)`` computes it (a NaN passes through)."""
        c, robot = self.client, self.robot
        toe_x, heel_x = FSR_X
        inner_y, outer_y = FSR_Y
        length, width = toe_x - heel_x, outer_y - inner_y
        fsr = [0.0] * 8
        contacts = pb.getContactPoints(bodyA=robot, physicsClientId=c)
        if not contacts:
            return fsr
        if self._next_piece is not None and self.terrain_reached < 0:  # the ground truth of issue 29's detectors
            edge = self._next_piece
            if any(contact[5][0] >= edge for contact in contacts if contact[3] in self.foot_index):
                self.terrain_reached = self.t
        feet = self.foot_index
        states = pb.getLinkStates(robot, feet, physicsClientId=c)  # both feet's frames in one call
        for k, (foot, state) in enumerate(zip(feet, states, strict=True)):
            on_foot = [contact for contact in contacts if contact[3] == foot]
            if not on_foot:
                continue
            (ox, oy, oz), turn = state[4:6]
            r0, r1, _, r3, r4, _, r6, r7, _ = pb.getMatrixFromQuaternion(turn)  # row-major; the foot's axes: columns
            side = 1.0 if k == 0 else -1.0  # the right foot is the left's mirror image in y
            toe_outer = toe_inner = heel_inner = heel_outer = 0.0
            for contact in on_foot:
                px, py, pz = contact[5]
                dx, dy, dz = px - ox, py - oy, pz - oz
                x = r0 * dx + r3 * dy + r6 * dz  # into the foot's frame
                y = side * (r1 * dx + r4 * dy + r7 * dz)
                toe = (x - heel_x) / length
                toe = 0.0 if 0.0 > toe else toe
                toe = 1.0 if 1.0 < toe else toe
                outer = (y - inner_y) / width
                outer = 0.0 if 0.0 > outer else outer
                outer = 1.0 if 1.0 < outer else outer
                force = contact[9]
                toe_inner += force * toe * (1 - outer)
                toe_outer += force * toe * outer
                heel_inner += force * (1 - toe) * (1 - outer)
                heel_outer += force * (1 - toe) * outer
            fsr[4 * k : 4 * k + 4] = toe_inner, toe_outer, heel_inner, heel_outer
        return fsr

    def sense(self) -> np.ndarray:
        fsr = self._foot_pressure()
        up0, up1, up2 = self.torso_turn[2].tolist()  # the world's vertical in the torso's frame
        spin0, spin1 = self.torso_spin[:2].tolist()
        imu = [math.atan2(-up0, up2), math.atan2(up1, up2), spin1, spin0]
        feet = [fsr[2] + fsr[3], fsr[0] + fsr[1], fsr[6] + fsr[7], fsr[4] + fsr[5]]  # heel_l, toe_l, heel_r, toe_r
        q, dq, tau = self._joint_lists
        values = np.array(q + dq + tau + feet + fsr + imu + [self.back])
        return np.minimum(np.maximum(values, SENSOR_LOW, out=values), SENSOR_HIGH, out=values)  # the sensors saturate

    # ------------------------------------------------------------------ acting
    def actuate(self, command: np.ndarray) -> None:
        p, c, robot, joints = self.params, self.client, self.robot, self.joint_index
        target = np.minimum(np.maximum(command, LOWER), UPPER).tolist()
        h = p.control_dt / p.substeps
        rate, stiffness = p.servo_rate, p.servo_stiffness
        back = 0.0  # N s pressing the robot forward this tick (a push, the ball): the touch sensor `back`
        # per physics step, in plain floats (12 joints: cheaper than numpy's calls, the same IEEE operations); each
        # clip written so that a NaN passes through as np.minimum / np.maximum pass it
        q, energy = self.q.tolist(), self.energy
        set_motors, step, joint_states = pb.setJointMotorControlArray, pb.stepSimulation, pb.getJointStates
        steps = []  # each physics step's joint torques, N m
        for k in range(p.substeps):
            speed, torque = [], []
            for goal, angle, fastest, effort in zip(target, q, _SPEED, _EFFORT, strict=True):
                error = goal - angle
                v = rate * error  # the servo's speed target, within +-its speed
                speed.append(-fastest if v < -fastest else (fastest if v > fastest else v))
                most = stiffness * abs(error) + HOLD_TORQUE  # the most torque it may use, within its effort
                torque.append(effort if most > effort else most)
            set_motors(robot, joints, pb.VELOCITY_CONTROL, targetVelocities=speed, forces=torque, physicsClientId=c)
            if self.push_force > 0 and self.push_start <= self.t + k * h < self.push_end:
                self._push(self.t + k * h)  # an external force lasts one step: applied every step of the push
                back += max(float(self.push_vector[0]), 0.0) * h
            if self.ball_mass > 0 and self.t + k * h >= self.ball_time - 1e-9 and not self._ball_thrown:
                self._throw()
            step(physicsClientId=c)
            if self._ball_thrown and self.t + k * h < self.ball_time + BALL_WATCH:
                back += self._ball_contacts(self.t + (k + 1) * h, h)
            states = joint_states(robot, joints, physicsClientId=c)
            q = [state[0] for state in states]
            torques = [state[3] for state in states]
            steps.append(torques)
        for power in _motor_powers(steps):  # (5.5)-(5.6), one step after the other
            energy += power * h
        dq = [state[1] for state in states]
        self.q, self.dq, self.tau = np.array(q), np.array(dq), np.array(torques)
        self._joint_lists = (q, dq, torques)
        self.energy = energy
        self.back = min(back / p.control_dt, MAX_BACK)
        self.ticks += 1
        self.t = self.ticks * p.control_dt
        self._read_torso()
        self._judge()
        if self._trace is not None:
            tick = self.ticks - 1
            if tick % self._signal_every == 0:
                forward = self.torso_turn[:, 0]  # the torso's x axis in the world: its heading on the ground
                where = (*self.torso_position[:2], math.atan2(forward[1], forward[0]))
                self._trace.append((self.t, self.sense(), float(MOTOR @ self.tau**2), where))
            if tick % self._picture_every == 0:
                self._record_frame()

    def _push(self, t: float) -> None:
        com = pb.getBasePositionAndOrientation(self.robot, physicsClientId=self.client)[0]
        pb.applyExternalForce(
            self.robot, -1, self.push_vector.tolist(), com, pb.WORLD_FRAME, physicsClientId=self.client
        )
        if self._pushes is not None:
            self._pushes.append((t, com, self.push_vector))

    def _throw(self) -> None:
        """The ball leaves BALL_GAP m behind the torso's centre of mass at ``ball_speed``, aimed to arrive at
        ``ball_height`` above it (its upward speed cancels gravity's drop over the flight)."""
        c = self.client
        com = pb.getBasePositionAndOrientation(self.robot, physicsClientId=c)[0]
        flight = BALL_GAP / self.ball_speed if self.ball_speed > 0 else 0.0
        start = (com[0] - BALL_GAP, com[1], com[2] + self.ball_height)
        pb.resetBasePositionAndOrientation(self.ball, start, (0, 0, 0, 1), physicsClientId=c)
        pb.resetBaseVelocity(self.ball, (self.ball_speed, 0.0, G * flight / 2), (0, 0, 0), physicsClientId=c)
        self._ball_thrown = True

    def _ball_contacts(self, t: float, h: float) -> float:
        """The ball's contact forces on the robot over this physics step: forward impulse and peak, arrows; returns
        the forward impulse of this step (N s; 0 when it presses backward)."""
        contacts = pb.getContactPoints(bodyA=self.ball, bodyB=self.robot, physicsClientId=self.client)
        if not contacts:
            return 0.0
        force = sum(np.array(ct[7]) * -ct[9] for ct in contacts)  # on the robot (the normal on B points to A)
        self.ball_impulse += float(force[0]) * h  # forward: a ball that comes to rest on a foot adds its weight only
        self.ball_peak = max(self.ball_peak, float(force[0]))
        if self._pushes is not None:
            self._pushes.append((t, np.array(contacts[0][6]), force))
        return max(float(force[0]), 0.0) * h

    def _judge(self) -> None:
        """Fall, lane, finish line (once per control tick)."""
        p = self.params
        x, y, z = self.torso_position
        up = self.torso_turn[2]
        pitch, roll = math.atan2(-up[0], up[2]), math.atan2(up[1], up[2])
        limit = math.radians(p.fall_angle_deg)
        low = z - self.ground_height(x) < p.fall_height_fraction * self.start_height
        self.fell = low or abs(pitch) > limit or abs(roll) > limit
        self.left_lane = abs(y) > p.lane_half_width
        if x >= p.finish_line and not (self.fell or self.left_lane):
            self.finished = True
            self.finish_time = self.t

    @property
    def done(self) -> bool:
        return self.fell or self.left_lane or self.finished or self.t >= self.params.duration - 1e-9

    METRICS: ClassVar[dict[str, str]] = {
        "distance": "m",
        "lateral": "m",
        "time": "s",
        "velocity": "m/s",
        "energy": "J",
        "mean_power": "W",
        "fell": "",
        "left_lane": "",
        "timed_out": "",
        "ball_impulse": "N s",
        "ball_peak_force": "N",
    }

    def outcome(self) -> tuple[bool, float, dict]:
        p = self.params
        distance = float(self.torso_position[0])
        success = self.finished
        # (5.7)-(5.8): E_k = m v_a^2 / 2 with v_a = trajectory length / time; eta = E_k / E_e
        eta = walking_efficiency(self.mass, p.finish_line / self.finish_time, self.energy) if success else 0.0
        metrics = {
            "distance": distance,
            "lateral": float(self.torso_position[1]),
            "time": self.t,
            "velocity": distance / self.t if self.t > 0 else 0.0,
            "energy": self.energy,
            "mean_power": self.energy / self.t if self.t > 0 else 0.0,
            "fell": self.fell,
            "left_lane": self.left_lane,
            "timed_out": not (success or self.fell or self.left_lane),
        }
        if self.ball_mass > 0:
            metrics |= {"ball_impulse": self.ball_impulse, "ball_peak_force": self.ball_peak}
        if self._next_piece is not None:  # s: when a foot first touched the next piece of ground (-1: never)
            metrics["terrain_reached"] = self.terrain_reached
        return success, eta, metrics

    # ------------------------------------------------------------------ telemetry
    def _record_frame(self) -> None:
        """Where every link is (torso frame and the 12 child frames) and the feet's contact forces."""
        c, robot = self.client, self.robot
        com, orientation = pb.getBasePositionAndOrientation(robot, physicsClientId=c)
        torso = pb.multiplyTransforms(com, orientation, *self._to_link)
        states = pb.getLinkStates(robot, self._picture_links, physicsClientId=c)
        poses = [torso] + [(s[4], s[5]) for s in states]
        forces = []
        contacts = pb.getContactPoints(bodyA=robot, physicsClientId=c)
        for foot in self.foot_index:
            points = [ct for ct in contacts if ct[3] == foot]
            total = sum(ct[9] for ct in points)
            if total <= 0:
                forces.append(np.zeros(6))
                continue
            centre = sum(np.array(ct[5]) * ct[9] for ct in points) / total  # centre of pressure
            force = sum(np.array(ct[7]) * -ct[9] for ct in points)  # on the foot (normal on B points to A)
            forces.append(np.concatenate([centre, force]))
        self._frames.append((self.t, poses, np.array(forces)))

    def log_trial(self, trial_id: int) -> None:
        """A logged trial on ``sim_time`` (trial k starts at k x duration): joint and torso angles (deg), the gyro's
        rates (deg/s), the torso's path on the ground (x, y in m, heading in deg), foot pressures (N) and motor power
        (W) at ``rates.signals_hz``; every NAO link as a box and the feet's
        contact forces as arrows (side view: x, z) at ``rates.pictures_hz``; the ground's boxes; a push as
        arrows at its every physics step and an event. (The trial's start and end: ``Body.log_outcome``.)"""
        if self.telemetry is None or not self._trace:
            return
        emit, t0 = self.telemetry.emit, trial_id * self.params.duration
        t = np.array([row[0] for row in self._trace])
        values = np.stack([row[1] for row in self._trace])
        power = np.array([row[2] for row in self._trace])
        times = t0 + t
        for j, name in enumerate(JOINT_NAMES):
            emit(series(f"joints/{name}", trial_id, times, np.degrees(values[:, j]), "deg"))
        index = {s.name: i for i, s in enumerate(SENSORS)}
        for name in ("torso_pitch", "torso_roll"):
            emit(series(f"torso/{name[6:]}", trial_id, times, np.degrees(values[:, index[name]]), "deg"))
        for name in ("torso_pitch_rate", "torso_roll_rate"):  # the gyro, about the torso's own axes
            emit(series(f"torso/{name[6:]}", trial_id, times, np.degrees(values[:, index[name]]), "deg/s"))
        where = np.array([row[3] for row in self._trace])  # the torso's centre of mass on the ground, its heading
        emit(series("path/x", trial_id, times, where[:, 0], "m"))
        emit(series("path/y", trial_id, times, where[:, 1], "m"))
        emit(series("path/heading", trial_id, times, np.degrees(np.unwrap(where[:, 2])), "deg"))
        for name in ("heel_l", "toe_l", "heel_r", "toe_r"):
            emit(series(f"feet/{name}", trial_id, times, values[:, index[name]], "N"))
        emit(series("power", trial_id, times, power, "W"))
        self._log_pictures(trial_id, t0)
        if self._pushes:
            pushes = self._pushes
            emit(
                Arrows2D(
                    "side/push",
                    trial_id,
                    t0 + np.array([row[0] for row in pushes]),
                    np.array([(row[1][0], row[1][2]) for row in pushes]),
                    np.array([(row[2][0], row[2][2]) for row in pushes]) / 100.0,  # 1 m per 100 N
                )
            )
            if self.ball_mass > 0:
                what = (
                    f"ball {self.ball_mass:g} kg at {self.ball_speed:g} m/s: {self.ball_impulse:.2f} N s, "
                    f"peak {self.ball_peak:.0f} N"
                )
            else:
                what = f"push {self.push_force:g} N for {self.push_end - self.push_start:g} s"
            emit(Event("events", trial_id, t0 + pushes[0][0], what))
        if self._next_piece is not None and self.terrain_reached >= 0:
            where = f"{self._next_slope:g} deg from x = {self._next_piece:.2f} m"
            what = f"a foot reaches the next piece of ground ({where})"
            emit(Event("events/terrain", trial_id, t0 + self.terrain_reached, what))

    def _log_pictures(self, trial_id: int, t0: float) -> None:
        frames = self._frames
        times = t0 + np.array([f[0] for f in frames])
        order = {link: k for k, link in enumerate(LINKS)}  # poses are in LINKS order (torso, then its children)
        owner = np.array([order[p.link] for p in PARTS])
        positions = np.array([[pose[0] for pose in f[1]] for f in frames])[:, owner].reshape(-1, 3)
        turns = np.array([[pose[1] for pose in f[1]] for f in frames])[:, owner].reshape(-1, 4)
        offsets = np.tile(np.array([p.com for p in PARTS]), (len(frames), 1))
        colors = np.array([_color(p) for p in PARTS], dtype=np.uint8)
        halves = np.array([p.size for p in PARTS]) / 2
        self.telemetry.emit(
            Boxes3D(
                "robot",
                trial_id,
                times,
                positions + _rotate(turns, offsets),
                halves,
                turns,
                len(PARTS),
                colors,
                follow=True,  # the view of the walk moves along x with the robot
            )
        )
        ground = self.ground_boxes
        self.telemetry.emit(
            Boxes3D(
                "ground",
                trial_id,
                times[:1],
                np.array([g[0] for g in ground]),
                np.array([g[1] for g in ground]),
                np.array([g[2] for g in ground]),
                len(ground),
                np.tile(np.array([(120, 100, 80)], dtype=np.uint8), (len(ground), 1)),
            )
        )
        forces = np.stack([f[2] for f in frames])  # (frames, foot, centre + force)
        for k, foot in enumerate(FEET):
            self.telemetry.emit(
                Arrows2D(
                    f"side/contact_{foot[-1]}",
                    trial_id,
                    times,
                    forces[:, k][:, [0, 2]],
                    forces[:, k][:, [3, 5]] / 100.0,  # 1 m per 100 N
                    (40, 180, 80),
                )
            )

    def close(self) -> None:
        """Disconnect this body's PyBullet client."""
        if self.client is not None:
            pb.disconnect(physicsClientId=self.client)
            self.client, self._world_key, self._saved = None, None, None


def _motor_powers(steps: list[list[float]]) -> list[float]:
    """sum_i c_i tau_i^2 (W, (5.5)) of each physics step of a tick, ``steps`` its joint torques: one vectorised sum for
    the tick instead of one per step, and the same floats as ``MOTOR @ tau**2`` per step, bit for bit: that 12-term dot
    adds the joints' terms one after the other in joint order, and so does a running sum (``accumulate``, sequential
    by definition, where a plain sum would add in pairs; tests/bodies/test_humanoid_speed.py)."""
    terms = np.array(steps)  # (steps, joints)
    terms *= terms
    terms *= MOTOR
    return np.add.accumulate(terms, axis=1)[:, -1].tolist()


def _color(part) -> tuple[int, int, int]:
    """Left limbs blue, right limbs orange, torso and head grey."""
    if part.link.endswith("_l"):
        return (40, 110, 220)
    if part.link.endswith("_r"):
        return (230, 140, 30)
    return (150, 150, 150)
