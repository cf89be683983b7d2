"""The NAO V4.0 humanoid as one table of numbers: links, joints, motors, standing pose.

Everything the simulated humanoid (:mod:`sfl_brain.bodies.humanoid`) is built from, and what its
test checks the built body against. Sources, in ``/work/shared/CPG-HUMANOID.md`` (the digest):

* kinematics, masses and centres of mass: the ros-naoqi ``nao_description`` V4.0 URDF (BSD),
  digest §6; joint origins and axes as NAO's, so a joint angle here *is* NAO's angle (Aldebaran
  signs, radians, 0 = legs straight and arms pointing forward);
* driven joint limits: the author's ``MyNao.txt`` = Aldebaran's, digest §6;
* effort (N m) and velocity (rad/s) limits: the URDF figures of digest §6;
* motors and gear ratios: Aldebaran's V3.2/3.3 motor data, digest §6.

NAO's meshes are not freely licensed, so every NAO link is a solid box centred at that link's
centre of mass (the URDF's), with a size chosen here to look like NAO; its inertia is the box's.
Links that NAO moves with joints not driven here are fixed to their parent (HipYawPitch,
ShoulderRoll, the elbows, wrists and head at 0), so the simulated body has a torso and twelve
driven joints: shoulder pitch, hip roll, hip pitch, knee, ankle pitch and ankle roll, left and
right (thesis L1339).
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class Part:
    """One NAO link, fixed to a simulated ``link``: its mass and a box at its centre of mass."""

    name: str  # NAO's link name (V4.0 URDF)
    link: str  # the simulated link it belongs to
    mass: float  # kg, V4.0 URDF
    com: tuple[float, float, float]  # m, in the simulated link's frame (URDF CoM + that part's frame offset)
    size: tuple[float, float, float]  # m, the box's edge lengths (chosen here, NAO-like)
    collides: bool  # touches the ground (small links inside others do not)


@dataclass(frozen=True)
class Joint:
    """One driven joint: where it is, how it turns, how far, how hard and how fast."""

    name: str  # ours = the CPG circuit's (modules/cpg/circuits/humanoid_nao.yaml)
    nao: str  # Aldebaran's name
    parent: str
    child: str
    origin: tuple[float, float, float]  # m, in the parent link's frame
    axis: tuple[float, float, float]
    lower: float  # rad (MyNao.txt = Aldebaran)
    upper: float  # rad
    effort: float  # N m (URDF)
    velocity: float  # rad/s (URDF)
    gear_ratio: float  # motor turns per joint turn (Aldebaran)
    motor: str  # key of MOTORS
    plus: str  # what a positive rotation is: "extension" or "flexion" (author's MyNaoPsitiveAngle_E_or_F.txt)


@dataclass(frozen=True)
class Motor:
    """A Maxon DC motor as Aldebaran lists it (digest §6)."""

    no_load_rpm: float
    stall_torque: float  # N m at the motor shaft


MOTORS = {
    "RE-max 24": Motor(no_load_rpm=8000.0, stall_torque=0.0595),  # legs
    "RE-max 17": Motor(no_load_rpm=11900.0, stall_torque=0.0151),  # shoulders
}


def motor_coefficient(joint: Joint) -> float:
    """c in P = c tau^2, W per (N m)^2: the winding's R I^2 for joint torque tau (digest §6, item 9 of §0).

    A DC motor has k_t = U / omega_0 and R = U k_t / tau_stall, so R / k_t^2 = omega_0 / tau_stall, free
    of the unknown voltage U; the joint torque tau is N eta_g times the motor's, with eta_g = 1 (the gear
    efficiency is not published; 1 is chosen here and makes c a lower bound)."""
    motor = MOTORS[joint.motor]
    omega_0 = motor.no_load_rpm * 2 * math.pi / 60
    return omega_0 / motor.stall_torque / joint.gear_ratio**2


def _mirror(xyz: tuple[float, float, float]) -> tuple[float, float, float]:
    return (xyz[0], -xyz[1], xyz[2])


def _add(a, b) -> tuple[float, float, float]:
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


# --- NAO V4.0 URDF geometry (digest §6), left side; the right side is its mirror image in y -------------
HIP = (0.0, 0.050, -0.085)  # HipYawPitch = HipRoll = HipPitch, in the torso frame
THIGH = 0.100  # hip -> knee
TIBIA = 0.1029  # knee -> ankle pitch = ankle roll
SOLE = 0.04511  # ankle -> sole, straight down
SHOULDER = (0.0, 0.098, 0.100)  # ShoulderPitch, in the torso frame
NECK = (0.0, 0.0, 0.1265)  # HeadYaw, in the torso frame
ELBOW = (0.105, 0.015, 0.0)  # ElbowYaw, in the shoulder frame
WRIST = (0.05595, 0.0, 0.0)  # WristYaw, in the elbow frame
#: foot pressure sensors (FSR) in the foot frame: x of the front and rear pair, y inner and outer of the
#: left foot (digest §6: x = +0.070 / -0.030, y = +-0.023 / +-0.030; the outer is +y on the left)
FSR_X = (0.070, -0.030)  # toe, heel
FSR_Y = (-0.023, 0.030)  # inner, outer (left foot; mirrored on the right)

_LEFT_PARTS = (
    # name, link, mass kg, CoM in the link frame m, box m, collides
    ("Shoulder", "arm", 0.07504, (-0.00165, -0.02663, 0.00014), (0.04, 0.04, 0.04), False),
    ("Bicep", "arm", 0.15777, (0.02455, 0.00563, 0.0033), (0.09, 0.05, 0.05), True),
    ("Elbow", "arm", 0.06483, _add(ELBOW, (-0.02744, 0.0, -0.00014)), (0.03, 0.04, 0.04), False),
    ("ForeArm", "arm", 0.07761, _add(ELBOW, (0.02556, 0.00281, 0.00076)), (0.05, 0.045, 0.045), True),
    ("Hand", "arm", 0.18533, _add(_add(ELBOW, WRIST), (0.03434, -0.00088, 0.00308)), (0.07, 0.045, 0.045), True),
    ("Pelvis", "torso", 0.06981, _add(HIP, (-0.00781, -0.01114, 0.02661)), (0.04, 0.04, 0.05), False),
    ("Hip", "hip", 0.13053, (-0.01549, 0.00029, -0.00515), (0.05, 0.04, 0.04), False),
    ("Thigh", "thigh", 0.38968, (0.00138, 0.00221, -0.05373), (0.06, 0.06, 0.10), True),
    ("Tibia", "tibia", 0.29142, (0.00453, 0.00225, -0.04936), (0.06, 0.06, 0.10), True),
    ("ankle", "ankle", 0.13416, (0.00045, 0.00029, 0.00685), (0.04, 0.04, 0.03), False),
    # the sole box's bottom is the sole (z = -SOLE): centred at the CoM z, its height is 2 (SOLE + com_z);
    # 0.16 x 0.09: NAO's real sole (digest §6; the URDF's fallback box is 0.16 x 0.06)
    ("sole", "foot", 0.16184, (0.02542, 0.0033, -0.03239), (0.16, 0.09, 2 * (SOLE - 0.03239)), True),
)


def _parts() -> tuple[Part, ...]:
    parts = [
        Part("torso", "torso", 1.04956, (-0.00413, 0.0, 0.04342), (0.09, 0.14, 0.166), True),
        Part("Neck", "torso", 0.06442, _add(NECK, (-0.00001, 0.0, -0.02742)), (0.03, 0.03, 0.05), False),
        Part("Head", "torso", 0.60533, _add(NECK, (-0.00112, 0.0, 0.05258)), (0.11, 0.13, 0.11), True),
    ]
    for side, mirror in (("l", lambda v: v), ("r", _mirror)):
        for name, link, mass, com, size, collides in _LEFT_PARTS:
            own = "torso" if link == "torso" else f"{link}_{side}"
            parts.append(Part(f"{side.upper()}{name}", own, mass, mirror(com), size, collides))
    return tuple(parts)


#: every NAO link as simulated, torso first
PARTS: tuple[Part, ...] = _parts()

#: simulated links, parent before child (the torso is PyBullet's base)
LINKS: tuple[str, ...] = ("torso",) + tuple(
    f"{link}_{side}" for side in "lr" for link in ("arm", "hip", "thigh", "tibia", "ankle", "foot")
)

#: motor kind: effort N m, velocity rad/s (URDF, digest §6), gear ratio and motor (Aldebaran, §6)
_KINDS = {
    "roll": dict(effort=3.348, velocity=4.16174, gear_ratio=201.3, motor="RE-max 24"),  # reduction type A
    "pitch": dict(effort=3.023, velocity=6.40239, gear_ratio=130.85, motor="RE-max 24"),  # type B
    "shoulder": dict(effort=1.329, velocity=8.26797, gear_ratio=150.27, motor="RE-max 17"),  # type A
}
X, Y, AT = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 0.0)
E, F = "extension", "flexion"

# name, NAO's name, parent, child, origin, axis, lower, upper (rad), kind, + =
_JOINT_ROWS = (
    ("shoulder_pitch_l", "LShoulderPitch", "torso", "arm_l", SHOULDER, Y, -2.0857, 2.0857, "shoulder", F),
    ("shoulder_pitch_r", "RShoulderPitch", "torso", "arm_r", _mirror(SHOULDER), Y, -2.0857, 2.0857, "shoulder", F),
    ("hip_roll_l", "LHipRoll", "torso", "hip_l", HIP, X, -0.379472, 0.790477, "roll", E),
    ("hip_roll_r", "RHipRoll", "torso", "hip_r", _mirror(HIP), X, -0.790477, 0.379472, "roll", F),
    ("hip_pitch_l", "LHipPitch", "hip_l", "thigh_l", AT, Y, -1.535889, 0.484090, "pitch", E),
    ("hip_pitch_r", "RHipPitch", "hip_r", "thigh_r", AT, Y, -1.535889, 0.484090, "pitch", E),
    ("knee_l", "LKneePitch", "thigh_l", "tibia_l", (0.0, 0.0, -THIGH), Y, -0.092346, 2.112528, "pitch", F),
    ("knee_r", "RKneePitch", "thigh_r", "tibia_r", (0.0, 0.0, -THIGH), Y, -0.103083, 2.120198, "pitch", F),
    ("ankle_pitch_l", "LAnklePitch", "tibia_l", "ankle_l", (0.0, 0.0, -TIBIA), Y, -1.189516, 0.922747, "pitch", E),
    ("ankle_pitch_r", "RAnklePitch", "tibia_r", "ankle_r", (0.0, 0.0, -TIBIA), Y, -1.186448, 0.932056, "pitch", E),
    ("ankle_roll_l", "LAnkleRoll", "ankle_l", "foot_l", AT, X, -0.397880, 0.769001, "roll", F),
    ("ankle_roll_r", "RAnkleRoll", "ankle_r", "foot_r", AT, X, -0.768992, 0.397935, "roll", E),
)

#: the twelve driven joints, in the order of the body's commands; limits per side as Aldebaran lists them
JOINTS: tuple[Joint, ...] = tuple(
    Joint(name, nao, parent, child, origin, axis, lower, upper, **_KINDS[kind], plus=plus)
    for name, nao, parent, child, origin, axis, lower, upper, kind, plus in _JOINT_ROWS
)

#: total mass, kg (digest §6: V4.0 5.195; the thesis's 4.3 kg, L1430, is an older figure)
TOTAL_MASS = sum(p.mass for p in PARTS)
#: hip joint to sole with the leg straight, m
LEG_LENGTH = THIGH + TIBIA + SOLE

#: the standing pose, rad: the author's posture (digest §5: hip pitch -0.4, knee 0.7, ankle pitch -0.35,
#: hip roll +-2 deg with L +, R -), the shoulders at 1.4 (arms down, as the CPG circuit's theta0) and the
#: ankle rolls chosen here as minus the hip rolls, so that both soles are flat (the author's +-2 deg with
#: the hip's signs would stand each foot on its inner edge, 4 deg)
STANDING: dict[str, float] = {
    "shoulder_pitch_l": 1.4,
    "shoulder_pitch_r": 1.4,
    "hip_roll_l": math.radians(2.0),
    "hip_roll_r": -math.radians(2.0),
    "hip_pitch_l": -0.4,
    "hip_pitch_r": -0.4,
    "knee_l": 0.7,
    "knee_r": 0.7,
    "ankle_pitch_l": -0.35,
    "ankle_pitch_r": -0.35,
    "ankle_roll_l": -math.radians(2.0),
    "ankle_roll_r": math.radians(2.0),
}
