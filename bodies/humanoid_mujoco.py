"""The NAO-sized humanoid on MuJoCo (issue 31): the body of ``humanoid.py`` with another physics engine.

The same robot (``humanoid_mjcf.py`` generates it from ``humanoid_table.py``, as the URDF is), the same sensors and
commands (``SENSORS``, ``COMMANDS``: the CPG circuit drives it unchanged), the same servo law, trial, conditions,
judging, energy (5.5)-(5.6), outcome and telemetry: :class:`HumanoidMujoco` is a :class:`Humanoid` whose
engine-specific methods (building the world, placing the robot, reading joints, torso and contacts, stepping) go to a
:class:`MujocoWorld`; ``sense``, ``_judge``, ``outcome``, ``log_trial`` and the trial parameters are the PyBullet
body's own.

Chosen in a scenario by ``modules.body.params.physics: mujoco`` on the ``humanoid`` body or by the body
``humanoid_mujoco`` (the same class, ``physics`` mujoco by default). MuJoCo is an optional extra
(``pip install -e '.[mujoco]'``); it is imported when a MuJoCo body is made, never by the core, and without it
``physics: mujoco`` is refused by ``sfl check`` with the command that installs it.

**Servo** (``Humanoid.actuate``'s law, every physics step): speed target ``servo_rate * (q_cmd - q)`` clipped to the
joint's speed, torque at most ``servo_stiffness * |q_cmd - q| + HOLD_TORQUE`` within the joint's effort. PyBullet
reaches the speed target with a velocity-motor constraint limited by that cap; here a clutch does (a tendon between the
joint and a rotor turned at the speed target, its friction loss the cap: ``humanoid_mjcf.py``), and the torque the
sensors and the energy read is the clutch's constraint force over the step.

**Speed and determinism.** One model per terrain (and ball or not), compiled once; every trial resets the data to the
saved start (``mj_resetData``, then the start's positions): MuJoCo keeps no contact cache across steps, so the same
request gives the same trial bit for bit whatever ran before (tests/bodies/test_humanoid_mujoco.py).
"""

from __future__ import annotations

import importlib
import math
from typing import Literal

import numpy as np
from pydantic import Field

from sfl_brain.bodies.humanoid import (
    BALL_GAP,
    BALL_RADIUS,
    BALL_WATCH,
    CLEARANCE,
    EFFORT,
    FEET,
    GROUND_THICKNESS,
    HOLD_TORQUE,
    JOINT_NAMES,
    LOWER,
    MAX_BACK,
    MOTOR,
    SPEED,
    UPPER,
    G,
    Humanoid,
    HumanoidParams,
    N,
)
from sfl_brain.bodies.humanoid_mjcf import TREE_ORDER, world_mjcf
from sfl_brain.bodies.humanoid_table import FSR_X, FSR_Y, LINKS, PARTS, SOLE, STANDING
from sfl_brain.messages import TrialRequest

EXTRA = "pip install -e '.[mujoco]'"  # what installs MuJoCo with sfl-brain (pyproject's optional extra)


def import_mujoco():
    """The ``mujoco`` module, or an ImportError that names the extra which installs it."""
    try:
        return importlib.import_module("mujoco")
    except ImportError as exc:
        raise ImportError(
            f"physics: mujoco needs MuJoCo, an optional extra of sfl-brain: {EXTRA} (or pip install mujoco); {exc}"
        ) from None


def _turn_y(angle: float) -> tuple[float, float, float, float]:
    """The quaternion (x, y, z, w) of a turn by ``angle`` rad about +y."""
    return (0.0, math.sin(angle / 2), 0.0, math.cos(angle / 2))


def _wxyz_to_xyzw(q) -> tuple[float, float, float, float]:
    return (float(q[1]), float(q[2]), float(q[3]), float(q[0]))


GROUND, ROBOT, BALL = 1, 2, 3  # geom kinds


class MujocoWorld:
    """The engine-specific part: a MuJoCo model of one terrain (and ball or not), its data, the servo step and the
    reads the body's sensors are made of. Nothing here judges a trial."""

    def __init__(self, ground_boxes, params: HumanoidParams, ball: bool) -> None:
        mj = self.mj = import_mujoco()
        h = params.control_dt / params.substeps
        xml = world_mjcf(
            ground_boxes,
            h,
            friction=params.friction,
            ball_radius=BALL_RADIUS if ball else None,
            ball_at=(-1e3, 0.0, -1e3),  # parked until the first trial places it
        )
        self.model = model = mj.MjModel.from_xml_string(xml)
        self.data = mj.MjData(model)
        body = {model.body(i).name: i for i in range(model.nbody)}
        self.torso_body = body["torso"]
        self.link_body = [body[link] for link in LINKS]  # the pictures' order
        self.feet = [body[foot] for foot in FEET]
        # the servos work in MuJoCo's joint order (contiguous slices); ``order`` maps it to JOINTS', ``inverse`` back
        self.order = np.array([JOINT_NAMES.index(name) for name in TREE_ORDER])
        self.inverse = np.argsort(self.order)
        qpos = [model.jnt_qposadr[model.joint(name).id] for name in TREE_ORDER]
        dofs = [model.jnt_dofadr[model.joint(name).id] for name in (*TREE_ORDER, *(f"rotor_{n}" for n in TREE_ORDER))]
        assert qpos == list(range(7, 7 + N)) and dofs == list(range(6, 6 + 2 * N)), (qpos, dofs)
        d = self.data
        self.angles, self.speeds, self.rotor_speeds = d.qpos[7 : 7 + N], d.qvel[6 : 6 + N], d.qvel[6 + N : 6 + 2 * N]
        self.cap = model.tendon_frictionloss  # (N,), a view: the clutches' torque cap, set every step
        self.fastest, self.effort, self.motor = SPEED[self.order], EFFORT[self.order], MOTOR[self.order]
        self.target = self.angles.copy()
        self._slowest, self._error, self._buffer = -self.fastest, np.zeros(N), np.zeros(N)
        self.tau = np.zeros(N)  # the clutches' torques over the last step, MuJoCo's order
        mj.mj_forward(model, d)  # the clutches' friction rows come first among the constraints, in tendon order
        friction = int(mj.mjtConstraint.mjCNSTR_FRICTION_TENDON)
        assert (d.efc_type[:N] == friction).all() and (d.efc_id[:N] == np.arange(N)).all()
        # every geom's kind (0 none, 1 ground, 2 robot, 3 ball) and body, for the contacts
        self.geom_body = model.geom_bodyid.copy()
        self.geom_kind = np.zeros(model.ngeom, dtype=int)
        self.geom_kind[[model.geom(f"ground_{k}").id for k in range(len(ground_boxes))]] = GROUND
        self.geom_kind[np.isin(self.geom_body, self.link_body)] = ROBOT
        self._kind = self.geom_kind.tolist()
        self.elliptic = model.opt.cone == mj.mjtCone.mjCONE_ELLIPTIC
        self._foot_of = [self.feet.index(b) if b in self.feet else -1 for b in self.geom_body.tolist()]  # 0, 1, -1
        self.ball = body.get("ball")
        if ball:
            self.geom_kind[model.geom("ball").id] = BALL
            self.ball_qpos = model.jnt_qposadr[model.joint("ball").id]
            self.ball_qvel = model.jnt_dofadr[model.joint("ball").id]
        self.rate, self.stiffness = params.servo_rate, params.servo_stiffness
        self.start: np.ndarray | None = None  # qpos of the start, saved by the body

    # ------------------------------------------------------------------ state
    def reset(self, qpos: np.ndarray) -> None:
        """Everything back to rest at positions ``qpos`` (time 0, no velocity, no contact, no applied force)."""
        mj, d = self.mj, self.data
        mj.mj_resetData(self.model, d)
        d.qpos[:] = qpos
        mj.mj_kinematics(self.model, d)  # positions only: no contact before the first step, as in PyBullet
        self.tau[:] = 0.0

    def set_joints(self, angles) -> None:
        """The joints at ``angles`` (rad, JOINTS order), at rest."""
        self.angles[:] = np.asarray(angles)[self.order]
        self.mj.mj_kinematics(self.model, self.data)

    def set_torso(self, position, quaternion_xyzw) -> None:
        """Put the torso's own frame at this pose (its free joint's position is that frame's origin)."""
        qx, qy, qz, qw = quaternion_xyzw
        self.data.qpos[0:3] = position
        self.data.qpos[3:7] = (qw, qx, qy, qz)
        self.mj.mj_kinematics(self.model, self.data)

    def torso_com(self) -> np.ndarray:
        return self.data.xipos[self.torso_body].copy()

    def joints(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Angles (rad), speeds (rad/s) and the last step's motor torques (N m), JOINTS order."""
        inverse = self.inverse
        return self.angles[inverse], self.speeds[inverse], self.tau[inverse]

    def torso(self) -> tuple[tuple, np.ndarray, np.ndarray]:
        """The torso's centre of mass (m), its frame's rotation matrix (columns: its axes in the world) and its spin
        in that frame (rad/s; a free joint's angular velocity is in the body's frame)."""
        d = self.data
        return (
            tuple(d.xipos[self.torso_body].tolist()),
            d.xmat[self.torso_body].reshape(3, 3).copy(),
            d.qvel[3:6].copy(),
        )

    # ------------------------------------------------------------------ acting
    def aim(self, target: np.ndarray) -> None:
        """The servos' position targets for the next steps (rad, JOINTS order, within the joints' limits)."""
        self.target = target[self.order]

    def step(self, push=None) -> float:
        """One physics step of the servo law (the module's docstring) toward the targets, with a ``push`` (N, world
        frame, at the torso's centre of mass) if given; returns the motors' power sum_i c_i tau_i^2 (W, (5.5))."""
        d, error, buffer = self.data, self._error, self._buffer
        np.subtract(self.target, self.angles, out=error)
        np.multiply(error, self.rate, out=buffer)
        np.minimum(np.maximum(buffer, self._slowest, out=buffer), self.fastest, out=self.rotor_speeds)  # speed target
        np.abs(error, out=buffer)
        np.minimum(
            np.add(np.multiply(buffer, self.stiffness, out=buffer), HOLD_TORQUE, out=buffer), self.effort, out=self.cap
        )
        if push is not None:
            d.xfrc_applied[self.torso_body, :3] = push
        self.mj.mj_step(self.model, d)
        if push is not None:
            d.xfrc_applied[self.torso_body, :3] = 0.0
        # each clutch's friction force is the torque it put on its joint over the step (the tendon is q - r)
        tau = self.tau
        tau[:] = d.efc_force[:N]
        return float(self.motor @ (tau * tau))

    # ------------------------------------------------------------------ contacts
    def _contacts(self, kind: int):
        """The robot's contacts with geoms of ``kind``: positions (n, 3), forces on the robot (n, 3, world), the
        robot's bodies (n,) and normal forces (n,, N). Elliptic cones with condim 3: a contact's first three
        constraint forces are its force in its own frame (normal, two tangents; MuJoCo's mj_contactForce)."""
        d = self.data
        n = d.ncon
        if n == 0:
            return None
        contact = d.contact
        geoms = contact.geom
        kinds = self.geom_kind[geoms]
        mine = (kinds[:, 1] == ROBOT) & (kinds[:, 0] == kind)  # the robot is geom2: the force pushes it along +n
        theirs = (kinds[:, 0] == ROBOT) & (kinds[:, 1] == kind)
        chosen = np.flatnonzero((mine | theirs) & (contact.efc_address >= 0))
        if len(chosen) == 0:
            return None
        if self.elliptic:
            local = d.efc_force[contact.efc_address[chosen][:, None] + np.arange(3)]
        else:  # pyramidal cones: the constraint forces are the pyramid's edges (see _pyramid_normal)
            local = np.zeros((len(chosen), 3))
            force = np.zeros(6)
            for row, i in enumerate(chosen.tolist()):
                self.mj.mj_contactForce(self.model, d, i, force)
                local[row] = force[:3]
        frames = contact.frame[chosen].reshape(-1, 3, 3)  # rows: the normal (geom1 -> geom2), two tangents
        sign = np.where(mine[chosen], 1.0, -1.0)
        force = sign[:, None] * np.einsum("ni,nij->nj", local, frames)
        bodies = self.geom_body[np.where(mine[chosen], geoms[chosen, 1], geoms[chosen, 0])]
        return contact.pos[chosen], force, bodies, local[:, 0]

    def foot_loads(self) -> list[list[tuple[float, float, float, float]]]:
        """Per foot, (x, y, z, normal force N) of its sole's contacts with the ground, in plain floats (a foot has a
        few; cheaper than numpy's calls). Elliptic cones: a contact's first constraint force is its normal force."""
        d = self.data
        loads = [[], []]
        if d.ncon == 0:
            return loads
        contact = d.contact
        kind, foot_of = self._kind, self._foot_of
        normal = d.efc_force if self.elliptic else self._pyramid_normal
        for i, ((g1, g2), address, (x, y, z)) in enumerate(
            zip(contact.geom.tolist(), contact.efc_address.tolist(), contact.pos.tolist(), strict=True)
        ):
            if address < 0:
                continue
            if kind[g1] == GROUND and foot_of[g2] >= 0:
                loads[foot_of[g2]].append((x, y, z, float(normal[address if self.elliptic else i])))
            elif kind[g2] == GROUND and foot_of[g1] >= 0:
                loads[foot_of[g1]].append((x, y, z, float(normal[address if self.elliptic else i])))
        return loads

    @property
    def _pyramid_normal(self) -> list[float]:
        """Every contact's normal force (N) from MuJoCo's mj_contactForce: with pyramidal cones (not shipped: the
        calibration compares them) the constraint forces are the pyramid's edges, not the normal force."""
        force = np.zeros(6)
        out = []
        for i in range(self.data.ncon):
            self.mj.mj_contactForce(self.model, self.data, i, force)
            out.append(float(force[0]))
        return out

    def foot_contacts(self) -> list[tuple[np.ndarray, np.ndarray, np.ndarray] | None]:
        """Per foot, its sole's contacts with the ground: positions (n, 3), forces on the foot (n, 3), normal forces
        (n,, N); None for a foot off the ground."""
        found = self._contacts(GROUND)
        if found is None:
            return [None, None]
        position, force, bodies, normal = found
        out = []
        for foot in self.feet:
            on = bodies == foot
            out.append((position[on], force[on], normal[on]) if on.any() else None)
        return out

    def foot_frames(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Each foot's frame: origin (3,) and rotation (3, 3; columns: its axes in the world)."""
        d = self.data
        return [(d.xpos[b].copy(), d.xmat[b].reshape(3, 3).copy()) for b in self.feet]

    def foot_frames_flat(self) -> tuple[list, list]:
        """Both feet's origins and row-major rotation matrices, as plain floats."""
        d, feet = self.data, self.feet
        return d.xpos[feet].tolist(), d.xmat[feet].tolist()

    def ball_contacts(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The ball's contacts with the robot: positions (n, 3) and forces on the robot (n, 3), or None."""
        found = self._contacts(BALL)
        return None if found is None else found[:2]

    def link_poses(self) -> list[tuple[tuple, tuple]]:
        """Every simulated link's frame (position, quaternion x y z w), in LINKS order."""
        d = self.data
        return [(tuple(d.xpos[b].tolist()), _wxyz_to_xyzw(d.xquat[b])) for b in self.link_body]

    def set_ball_mass(self, mass: float) -> None:
        """The ball's mass (kg) and a solid sphere's inertia."""
        self.model.body_mass[self.ball] = mass
        self.model.body_inertia[self.ball] = 0.4 * mass * BALL_RADIUS**2

    def throw(self, position, velocity, mass: float) -> None:
        """The ball, of ``mass`` kg, at ``position`` with ``velocity`` (world frame), not spinning."""
        d = self.data
        self.set_ball_mass(mass)
        a, v = self.ball_qpos, self.ball_qvel
        d.qpos[a : a + 3] = position
        d.qpos[a + 3 : a + 7] = (1.0, 0.0, 0.0, 0.0)
        d.qvel[v : v + 3] = velocity
        d.qvel[v + 3 : v + 6] = 0.0


class HumanoidMujocoParams(HumanoidParams):
    physics: Literal["mujoco"] = Field("mujoco", description="physics engine: this body's is MuJoCo")


class HumanoidMujoco(Humanoid):
    """NAO V4.0-sized humanoid on MuJoCo (boxes): the PyBullet body's sensors, commands, servo law and trials."""

    Params = HumanoidMujocoParams

    def __new__(cls, params: HumanoidParams | None = None, *, seed: int = 0):
        return object.__new__(cls)  # never dispatched back to PyBullet by Humanoid.__new__

    def __init__(self, params: HumanoidParams | None = None, *, seed: int = 0) -> None:
        import_mujoco()  # a missing extra fails here, with its name, not in the first trial
        super().__init__(params, seed=seed)
        self._worlds: dict = {}  # (terrain, ball or not) -> MujocoWorld, built once each
        self.world: MujocoWorld | None = None

    # ------------------------------------------------------------------ world
    def start_trial(self, request: TrialRequest) -> None:
        p = self.params
        body_params = request.body_params
        pieces = self._trial_conditions(body_params)
        self._next_piece = None  # terrain_reached reads PyBullet's contact points: not measured on MuJoCo (yet)
        key = (pieces, self.ball_mass > 0)
        if key not in self._worlds:
            self._worlds[key] = self._build(pieces, ball=self.ball_mass > 0)
        world = self.world = self._worlds[key]
        self.ground_x, self.ground_z, self.ground_boxes, self._start_pose, self.start_height = world.ground
        world.reset(world.start)
        if world.ball is not None:  # this trial's ball from the start, as PyBullet's body sets it
            world.set_ball_mass(self.ball_mass)
        start_noise = float(body_params.get("start_noise", p.start_noise))  # a trial may set its own
        if start_noise > 0:
            offsets = np.random.default_rng(request.seed).normal(0.0, start_noise, N)
            world.set_joints(np.clip(self._start_pose + offsets, LOWER, UPPER))
        self._begin_trial()  # the torques are 0 after a reset

    def _build(self, pieces: tuple[tuple[float, float], ...], ball: bool = False) -> MujocoWorld:
        """A world for ``pieces`` (and a ball): the model compiled, the robot placed standing at x = 0, that start
        saved."""
        ground_x, ground_z, ground_boxes = self._ground(pieces)
        self.ground_x, self.ground_z = ground_x, ground_z
        world = MujocoWorld(ground_boxes, self.params, ball)
        self.world = world
        pose, start_height = self._place(pieces[0][1])
        if ball:  # parked on the run-up, far behind the robot (the PyBullet body's place)
            x = -self.params.run_up + 2 * BALL_RADIUS
            world.throw((x, 0.0, self.ground_height(x) + BALL_RADIUS), (0.0, 0.0, 0.0), 1.0)
        world.start = world.data.qpos.copy()
        world.ground = (ground_x, ground_z, ground_boxes, pose, start_height)
        return world

    def _ground(self, pieces):
        """The profile's points and its boxes (centre, half sizes, quaternion x y z w): the PyBullet body's ground
        (``Humanoid._build_ground``), the first piece extended back by the run-up, the last forward by the run-out."""
        p = self.params
        lengths = [length for length, _ in pieces]
        lengths[0] += p.run_up
        lengths[-1] += p.run_out
        first = pieces[0][1]
        points = [(-p.run_up * math.cos(first), -p.run_up * math.sin(first))]
        for length, (_, slope) in zip(lengths, pieces, strict=True):
            x, z = points[-1]
            points.append((x + length * math.cos(slope), z + length * math.sin(slope)))
        boxes = []
        for (x0, z0), (x1, z1) in zip(points[:-1], points[1:], strict=True):
            length, slope = math.hypot(x1 - x0, z1 - z0), math.atan2(z1 - z0, x1 - x0)
            half = (length / 2, p.ground_width / 2, GROUND_THICKNESS / 2)
            centre = ((x0 + x1) / 2 + math.sin(slope) * half[2], 0.0, (z0 + z1) / 2 - math.cos(slope) * half[2])
            boxes.append((centre, half, _turn_y(-slope)))
        ground_x, ground_z = np.array(points).T
        return ground_x, ground_z, boxes

    def _place(self, slope: float) -> tuple[np.ndarray, float]:
        """Stand the robot at x = 0 as ``Humanoid._place`` does (the standing pose, the ankles pitched by ``slope``,
        the torso as upright as the pose makes it, its centre of mass at x = 0, the soles CLEARANCE above the
        ground); returns the pose and the start height of the torso's centre of mass above the ground."""
        world = self.world
        pose = np.array([STANDING[name] for name in JOINT_NAMES])
        pose[[JOINT_NAMES.index("ankle_pitch_l"), JOINT_NAMES.index("ankle_pitch_r")]] -= slope
        lean = -(STANDING["hip_pitch_l"] + STANDING["knee_l"] + STANDING["ankle_pitch_l"])
        world.set_joints(pose)
        turn = _turn_y(lean)
        world.set_torso((0.0, 0.0, 1.0), turn)
        com = world.torso_com()
        lowest = math.inf
        for foot, (position, rotation) in zip(FEET, world.foot_frames(), strict=True):
            sole = next(part for part in PARTS if part.link == foot and part.collides)
            corners = np.array(
                [
                    (sole.com[0] + dx * sole.size[0] / 2, sole.com[1] + dy * sole.size[1] / 2, -SOLE)
                    for dx in (-1, 1)
                    for dy in (-1, 1)
                ]
            )
            world_corners = position + corners @ rotation.T
            gaps = world_corners[:, 2] - np.interp(world_corners[:, 0] - com[0], self.ground_x, self.ground_z)
            lowest = min(lowest, float(gaps.min()))
        frame = world.data.qpos[0:3].copy()
        world.set_torso((frame[0] - com[0], frame[1], frame[2] - lowest + CLEARANCE), turn)
        com = world.torso_com()
        return pose, float(com[2] - self.ground_height(com[0]))

    # ------------------------------------------------------------------ sensing
    def _read_joints(self) -> None:
        self.q, self.dq, self.tau = self.world.joints()
        self._joint_lists = (self.q.tolist(), self.dq.tolist(), self.tau.tolist())  # as plain floats, for sense

    def _read_torso(self) -> None:
        self.torso_position, self.torso_turn, self.torso_spin = self.world.torso()

    def _foot_pressure(self) -> list[float]:
        """The 8 FSR forces (N, FSR_NAMES order), shared out as ``Humanoid._foot_pressure`` does: each sole
        contact's normal force split bilinearly between the toe and heel rows and the inner and outer columns (the
        shares add up to the force; a contact beyond a row or column counts as on it). Plain floats."""
        toe_x, heel_x = FSR_X
        inner_y, outer_y = FSR_Y
        length, width = toe_x - heel_x, outer_y - inner_y
        fsr = [0.0] * 8
        loads = self.world.foot_loads()
        if not (loads[0] or loads[1]):
            return fsr
        origins, turns = self.world.foot_frames_flat()
        for k, contacts in enumerate(loads):
            if not contacts:
                continue
            ox, oy, oz = origins[k]
            r0, r1, _, r3, r4, _, r6, r7, _ = turns[k]  # row-major; the foot's axes: columns
            side = 1.0 if k == 0 else -1.0  # the right foot is the left's mirror image in y
            toe_outer = toe_inner = heel_inner = heel_outer = 0.0
            for px, py, pz, force in contacts:
                dx, dy, dz = px - ox, py - oy, pz - oz
                x = r0 * dx + r3 * dy + r6 * dz  # into the foot's frame
                y = side * (r1 * dx + r4 * dy + r7 * dz)
                toe = min(max((x - heel_x) / length, 0.0), 1.0)
                outer = min(max((y - inner_y) / width, 0.0), 1.0)
                toe_inner += force * toe * (1 - outer)
                toe_outer += force * toe * outer
                heel_inner += force * (1 - toe) * (1 - outer)
                heel_outer += force * (1 - toe) * outer
            fsr[4 * k : 4 * k + 4] = toe_inner, toe_outer, heel_inner, heel_outer
        return fsr

    # ------------------------------------------------------------------ acting
    def actuate(self, command: np.ndarray) -> None:
        p, world = self.params, self.world
        world.aim(np.minimum(np.maximum(command, LOWER), UPPER))
        h = p.control_dt / p.substeps
        back = 0.0  # N s pressing the robot forward this tick (a push, the ball): the touch sensor `back`
        energy = self.energy
        for k in range(p.substeps):
            t = self.t + k * h
            push = None
            if self.push_force > 0 and self.push_start <= t < self.push_end:
                push = self.push_vector  # an external force lasts one step: applied every step of the push
                back += max(float(push[0]), 0.0) * h
                if self._pushes is not None:
                    self._pushes.append((t, world.torso_com(), push))
            if self.ball_mass > 0 and t >= self.ball_time - 1e-9 and not self._ball_thrown:
                self._throw()
            energy += world.step(push) * h  # (5.5)-(5.6)
            if self._ball_thrown and t < self.ball_time + BALL_WATCH:
                back += self._ball_contacts(t + h, h)
        self._read_joints()
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

    def _throw(self) -> None:
        """The ball leaves BALL_GAP m behind the torso's centre of mass at ``ball_speed``, aimed to arrive at
        ``ball_height`` above it (``Humanoid._throw``)."""
        com = self.world.torso_com()
        flight = BALL_GAP / self.ball_speed if self.ball_speed > 0 else 0.0
        start = (com[0] - BALL_GAP, com[1], com[2] + self.ball_height)
        self.world.throw(start, (self.ball_speed, 0.0, G * flight / 2), self.ball_mass)
        self._ball_thrown = True

    def _ball_contacts(self, t: float, h: float) -> float:
        """The ball's contact forces on the robot over this physics step (``Humanoid._ball_contacts``): forward
        impulse and peak, arrows; returns the forward impulse of this step (N s; 0 when it presses backward)."""
        found = self.world.ball_contacts()
        if found is None:
            return 0.0
        position, forces = found
        force = forces.sum(axis=0)
        self.ball_impulse += float(force[0]) * h
        self.ball_peak = max(self.ball_peak, float(force[0]))
        if self._pushes is not None:
            self._pushes.append((t, position[0], force))
        return max(float(force[0]), 0.0) * h

    # ------------------------------------------------------------------ telemetry
    def _record_frame(self) -> None:
        """Where every link is, and the feet's contact forces at their centres of pressure (as PyBullet's body)."""
        forces = []
        for found in self.world.foot_contacts():
            total = 0.0 if found is None else float(found[2].sum())
            if total <= 0:
                forces.append(np.zeros(6))
                continue
            position, force, normal = found
            forces.append(np.concatenate([normal @ position / total, force.sum(axis=0)]))
        self._frames.append((self.t, self.world.link_poses(), np.array(forces)))

    def close(self) -> None:
        """Drop this body's MuJoCo models."""
        self._worlds, self.world = {}, None
