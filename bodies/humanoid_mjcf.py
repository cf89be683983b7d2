"""The NAO-sized humanoid as a MuJoCo model (MJCF), generated from the same table as its URDF (issue 31).

``robot_mjcf()`` writes the robot of ``humanoid_table.py`` as ``humanoid.urdf_text()`` does: one MuJoCo body per
simulated link (torso first, on a free joint), its mass, centre of mass and full inertia tensor from
``humanoid.link_inertial`` (the parts' boxes, parallel axes), a box geom for every part that touches the ground, and a
hinge for every driven joint at the child's origin (NAO's origin, axis and limits). ``world_mjcf(ground_boxes, ...)``
adds the ground (static boxes, the PyBullet body's) and, when asked for, a free ball.

**The servos.** PyBullet's position servo (``Humanoid.actuate``: every physics step a speed target
``servo_rate (q_cmd - q)`` within the joint's speed, reached by a velocity-motor constraint whose force is at most
``servo_stiffness |q_cmd - q| + HOLD_TORQUE`` within the effort) is a slip clutch: a constraint that drives a velocity
to a target with a bounded force. MuJoCo has that constraint: friction loss, which drives a velocity to zero with a
force of at most ``frictionloss``, solved with the contacts. Each driven joint q gets a rotor r (a hinge on its own
body in the world, so heavy that the clutch cannot slow it) and a fixed tendon q - r with friction loss: the body sets
the rotor's speed to the speed target and the tendon's friction loss to the cap before every physics step
(``humanoid_mujoco.MujocoWorld.step``), and reads the torque the clutch applied from its constraint force. The law is
the PyBullet body's, written out in our code; only the constraint that enforces it is MuJoCo's.

Everything here that is not in the table is a MuJoCo setting, each with its source or its calibration
(``docs/calibration/humanoid_mujoco.py`` measures them beside PyBullet; docs/bodies/humanoid.md, "Two engines"):

* contact types: the robot does not collide with itself (PyBullet's default for a URDF); parents and children never do
  in MuJoCo, and the bit masks below keep the others apart too;
* friction: MuJoCo takes the larger of two geoms' coefficients (PyBullet their product); both the ground and the robot
  get the body's ``friction``, so the pair's is that value, as in PyBullet (robot 1.0 x ground ``friction``);
* the constants below.
"""

from __future__ import annotations

import numpy as np

from sfl_brain.bodies.humanoid_table import JOINTS, LINKS, PARTS

#: MuJoCo's integrator: semi-implicit Euler, its default (the servos are constraints, solved implicitly by MuJoCo's
#: solver; no actuator or joint damping for implicitfast to take; 12 % cheaper per step, measured)
INTEGRATOR = "Euler"
#: the servos' rotors: far below the ground, out of everything's way, and so heavy (kg m^2 about their axis) that a
#: clutch's few N m change their speed by under 1e-8 rad/s a step (the body sets it every step anyway)
ROTOR_Z, ROTOR_ARMATURE = -50.0, 1e6
#: the clutches' softness (time constant s, damping ratio): 2 physics steps, the stiffest MuJoCo allows (its refsafe
#: floor); PyBullet's motor constraint is hard. Calibrated (docs/calibration/humanoid_mujoco.py --servo, 2026-11-27):
#: 5 ms stands (51.0 N, 3.0 J) and walks both gaits 3/3; 10 ms: the open-loop gait falls 3/3 at 1.5 s, the CPG gait 1/3;
#: 20 ms: even standing falls
SERVO_SOLREF = (0.005, 1.0)
#: contact softness: (time constant s, damping ratio) and impedance (d0, d_width, width m, midpoint, power); MuJoCo's
#: rule: the time constant at least 2 physics steps (5 ms at 400 Hz). Calibrated (docs/calibration/humanoid_mujoco.py
#: --contact, 2026-11-27): 5, 10 and 20 ms all stand (51.0 N on the feet, sinking 1.0-1.3 mm; PyBullet 2.0 mm) and walk
#: both gaits 3/3 (CPG 12.4-13.1 s elliptic); 10 ms, the middle one. The impedance: stiffer than MuJoCo's default
#: (0.9, 0.95, 0.001), so that the robot's weight compresses the contact less (chosen here)
CONTACT_SOLREF = (0.01, 1.0)
CONTACT_SOLIMP = (0.95, 0.99, 0.001, 0.5, 2.0)
#: friction cone: elliptic, MuJoCo's accurate one (its pyramidal default approximates the cone by its edges). Measured
#: (--contact): pyramidal also stands and walks, but the CPG gait drifts further sideways (lateral up to 0.18 m against
#: 0.11 m at 10 ms, 0.37 against 0.16 at 20 ms, 3 seeds)
CONE = "elliptic"
#: MuJoCo's Newton solver converges in a few iterations (its default: 100 at most, tolerance 1e-8); the PyBullet
#: body's ``solver_iterations`` is its own solver's (projected Gauss-Seidel) and does not carry over
SOLVER_ITERATIONS = 50
#: contact bit masks: robot geoms collide with the ground and the ball, not with each other
ROBOT_TYPE, ROBOT_AFFINITY = 2, 1
GROUND_TYPE, GROUND_AFFINITY = 1, 2
BALL_TYPE, BALL_AFFINITY = 1, 1


def _xyz(values) -> str:
    return " ".join(repr(float(v)) for v in values)


def _inertial(link: str) -> str:
    from sfl_brain.bodies.humanoid import link_inertial  # the URDF's inertials, the same numbers

    mass, com, i = link_inertial(link)
    full = (i[0, 0], i[1, 1], i[2, 2], i[0, 1], i[0, 2], i[1, 2])
    return f'<inertial pos="{_xyz(com)}" mass="{mass!r}" fullinertia="{_xyz(full)}"/>'


def _geoms(link: str, friction: float) -> list[str]:
    return [
        f'<geom name="{p.name}" type="box" pos="{_xyz(p.com)}" size="{_xyz(np.array(p.size) / 2)}" '
        f'contype="{ROBOT_TYPE}" conaffinity="{ROBOT_AFFINITY}" friction="{friction!r} 0.005 0.0001"/>'
        for p in PARTS
        if p.link == link and p.collides
    ]


def _body(link: str, friction: float, depth: int) -> list[str]:
    """The MJCF of ``link`` and its children (the table's joints)."""
    pad = "  " * depth
    children = [j for j in JOINTS if j.parent == link]
    out = []
    for j in children:
        out.append(f'{pad}<body name="{j.child}" pos="{_xyz(j.origin)}">')
        out.append(
            f'{pad}  <joint name="{j.name}" type="hinge" axis="{_xyz(j.axis)}" limited="true" '
            f'range="{j.lower!r} {j.upper!r}"/>'
        )
        out.append(f"{pad}  {_inertial(j.child)}")
        out.extend(f"{pad}  {g}" for g in _geoms(j.child, friction))
        out.extend(_body(j.child, friction, depth + 1))
        out.append(f"{pad}</body>")
    return out


def _tree_order(link: str = "torso") -> list[str]:
    """The driven joints depth first, as MuJoCo numbers them (a joint, then its child's joints)."""
    out = []
    for j in JOINTS:
        if j.parent == link:
            out += [j.name, *_tree_order(j.child)]
    return out


#: the driven joints in MuJoCo's order (qpos 7.., qvel 6..); the rotors and clutches follow it too
TREE_ORDER: tuple[str, ...] = tuple(_tree_order())


def robot_mjcf(friction: float = 0.8) -> tuple[str, str]:
    """The robot's ``<body>`` tree (torso on a free joint) and its servos' rotors (bodies) and clutches (a
    ``<tendon>`` block), from the table."""
    assert LINKS[0] == "torso"
    body = ['<body name="torso">', '  <freejoint name="torso"/>', f"  {_inertial('torso')}"]
    body += [f"  {g}" for g in _geoms("torso", friction)]
    body += _body("torso", friction, 1)
    body.append("</body>")
    # the servos: a rotor per joint (its own body in the world, turned at the speed target) and a slip clutch between
    # it and the joint (a tendon q - r whose friction, the torque cap, is set every step)
    rotors, clutches = [], []
    by_name = {j.name: j for j in JOINTS}
    for k, j in enumerate(by_name[name] for name in TREE_ORDER):
        rotors += [
            f'<body name="rotor_{j.name}" pos="0 {k!r} {ROTOR_Z!r}">',
            f'  <joint name="rotor_{j.name}" type="hinge" axis="0 1 0" armature="{ROTOR_ARMATURE!r}"/>',
            '  <inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/>',
            "</body>",
        ]
        clutches.append(
            f'<fixed name="{j.name}" frictionloss="{j.effort!r}" solreffriction="{_xyz(SERVO_SOLREF)}">'
            f'<joint joint="{j.name}" coef="1"/><joint joint="rotor_{j.name}" coef="-1"/></fixed>'
        )
    return "\n".join(body + rotors), "\n".join(clutches)


def world_mjcf(
    ground_boxes,
    timestep: float,
    friction: float = 0.8,
    ball_radius: float | None = None,
    ball_at=(0.0, 0.0, 0.0),
) -> str:
    """A whole world: the ground (``(centre, half sizes, quaternion x y z w)`` boxes), the robot, a ball if
    ``ball_radius``; MuJoCo's options as the module's docstring says."""
    robot, clutches = robot_mjcf(friction)
    ground = []
    for k, (centre, half, (qx, qy, qz, qw)) in enumerate(ground_boxes):
        ground.append(
            f'<geom name="ground_{k}" type="box" pos="{_xyz(centre)}" size="{_xyz(half)}" '
            f'quat="{_xyz((qw, qx, qy, qz))}" contype="{GROUND_TYPE}" conaffinity="{GROUND_AFFINITY}" '
            f'friction="{friction!r} 0.005 0.0001"/>'
        )
    ball = []
    if ball_radius is not None:
        ball = [
            f'<body name="ball" pos="{_xyz(ball_at)}">',
            '  <freejoint name="ball"/>',
            f'  <inertial pos="0 0 0" mass="1.0" diaginertia="{_xyz([0.4 * ball_radius**2] * 3)}"/>',
            f'  <geom name="ball" type="sphere" size="{ball_radius!r}" contype="{BALL_TYPE}" '
            f'conaffinity="{BALL_AFFINITY}" friction="0.5 0.005 0.0001"/>',
            "</body>",
        ]
    solref, solimp = _xyz(CONTACT_SOLREF), _xyz(CONTACT_SOLIMP)
    return "\n".join(
        [
            '<mujoco model="nao_v40_boxes">',
            '  <compiler angle="radian" inertiafromgeom="false" autolimits="true"/>',
            f'  <option timestep="{timestep!r}" gravity="0 0 -9.81" integrator="{INTEGRATOR}" cone="{CONE}" '
            f'iterations="{SOLVER_ITERATIONS}"/>',
            f'  <default><geom solref="{solref}" solimp="{solimp}"/></default>',
            "  <worldbody>",
            *(f"    {line}" for line in ground),
            *(f"    {line}" for line in robot.splitlines()),
            *(f"    {line}" for line in ball),
            "  </worldbody>",
            "  <tendon>",
            *(f"    {line}" for line in clutches.splitlines()),
            "  </tendon>",
            "</mujoco>",
            "",
        ]
    )
