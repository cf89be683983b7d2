"""A planar RunBot-style biped on pymunk (thesis §3.4; Geng, Porr & Wörgötter's RunBot).

Links (metres, kilograms; RunBot II public figures where known):

* trunk: 0.10 x 0.06 box, 0.45 kg, its centre 0.04 m above the hip axis; its pitch is held
  by a rotary spring-damper to the world, as RunBot walks on a boom (with a free trunk this
  walker always falls; the boom is also why the thesis's walker is planar);
* thigh 0.142 m, 0.20 kg; shank 0.125 m, 0.08 kg; curved foot: a 0.02 m radius disc at the
  shank's end.

Hips and knees are driven by DC motors: the controller's command is the motor voltage V
of (3.6) and the torque is tau = K (V - k_e omega) (stall torque K V, back-EMF k_e), the
electrical power R I^2 with I = (V - k_e omega) / R is integrated for the energy E_e of (5.6).
Joint stops: hip [-70, 70] deg, knee [-110, 0] deg.

Angles the controller sees: ``hip_l``/``hip_r`` in RunBot's convention, 90 deg = thigh along the
trunk axis, larger = thigh swung forward; ``knee_l``/``knee_r`` 0 = straight, negative = flexed
(radians for both); ``contact_l``/``contact_r`` ground contact 0/1; ``slope`` of the ground under
the hip (radians, uphill positive); ``pitch`` of the trunk.

A trial fails when the trunk's centre of mass comes below a shank's (§3.4.3), or when the
walker makes no progress (the boom holds up a walker that stalls): success needs
``min_distance`` metres forward and ``min_steps`` steps in ``duration`` seconds.

Terrain: a constant slope ``slope_deg`` or a piecewise profile ``terrain``: a string of
``length:slope_deg`` pieces separated by commas, e.g. ``"0.5:0,1.0:6,1.0:-4"``.
"""

from __future__ import annotations

import math
from typing import ClassVar

import numpy as np
import pymunk
import pymunk.batch
from pydantic import Field

from sfl_brain.body import Body, BodyParams, walking_efficiency
from sfl_brain.messages import TrialRequest
from sfl_brain.signals import Signal
from sfl_brain.telemetry import Strips2D, rates_of, series

THIGH, SHANK, FOOT_R = 0.142, 0.125, 0.02
GROUND_R = 0.01  # ground segments' radius: the surface is this far above the profile
M_TRUNK, M_THIGH, M_SHANK = 0.45, 0.20, 0.08
TRUNK_W, TRUNK_H, TRUNK_UP = 0.10, 0.06, 0.04
HIP_LIMITS = (math.radians(-70), math.radians(70))
KNEE_LIMITS = (math.radians(-110), 0.0)
# the walker's picture: points [trunk, hip, left knee, left foot, right knee, right foot] as three strips
# of three points (trunk centre to hip, twice the hip: strips of one length are sent as one array)
_WALKER_STRIPS = np.array([[0, 1, 1], [1, 2, 3], [1, 4, 5]])
_WALKER_COLORS = np.array([(90, 90, 90), (40, 110, 220), (230, 140, 30)], dtype=np.uint8)
_GROUND_COLOR = np.array([(120, 100, 80)], dtype=np.uint8)

_TORQUE = pymunk.batch.BodyFields.TORQUE

_HIP = (math.pi / 2 + HIP_LIMITS[0], math.pi / 2 + HIP_LIMITS[1])  # RunBot's convention: 90 deg = along the trunk
MAX_VOLTAGE = 12.0  # commands are clipped to +-this
SENSORS = (
    Signal("hip_l", "rad", *_HIP, "left hip: 90 deg = thigh along the trunk, larger = swung forward"),
    Signal("hip_r", "rad", *_HIP, "right hip, as hip_l"),
    Signal("knee_l", "rad", *KNEE_LIMITS, "left knee: 0 = straight, negative = flexed"),
    Signal("knee_r", "rad", *KNEE_LIMITS, "right knee, as knee_l"),
    Signal("contact_l", "", 0.0, 1.0, "left foot on the ground (1) or not (0), with hysteresis"),
    Signal("contact_r", "", 0.0, 1.0, "right foot on the ground"),
    Signal("slope", "rad", -math.radians(45), math.radians(45), "ground slope under the hip, uphill positive"),
    Signal("pitch", "rad", -math.pi, math.pi, "trunk pitch, counter-clockwise positive (it walks toward +x)"),
)
COMMANDS = (
    Signal("v_hip_l", "V", -MAX_VOLTAGE, MAX_VOLTAGE, "left hip motor voltage (3.6), clipped"),
    Signal("v_hip_r", "V", -MAX_VOLTAGE, MAX_VOLTAGE, "right hip motor voltage"),
    Signal("v_knee_l", "V", -MAX_VOLTAGE, MAX_VOLTAGE, "left knee motor voltage"),
    Signal("v_knee_r", "V", -MAX_VOLTAGE, MAX_VOLTAGE, "right knee motor voltage"),
)


#: steepest ground a slope or a terrain piece may have, degrees either way
MAX_SLOPE_DEG = 45.0
TERRAIN_SYNTAX = "pieces `length:slope_deg` separated by commas, e.g. '0.5:0,1.0:6,1.0:-4'"


def _slope(value, where: str = "") -> float:
    where = f"{where}: " if where else ""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValueError(f"{where}expected a number of degrees; got {value!r}")
    if not math.isfinite(value) or abs(value) > MAX_SLOPE_DEG:
        raise ValueError(f"{where}expected a slope within +-{MAX_SLOPE_DEG:g} deg; got {value!r}")
    return float(value)


def parse_terrain(profile) -> list[tuple[float, float]]:
    """(length m, slope deg) pieces of a terrain profile ``"0.5:0,1.0:6"`` ('' for none); ValueError if
    malformed. Stricter than the body at run time: lengths in (0, 1000] m, slopes within MAX_SLOPE_DEG."""
    if profile == "":
        return []  # no profile: the constant slope_deg
    if not isinstance(profile, str) or not profile.strip():
        number = isinstance(profile, int | float) and not isinstance(profile, bool)
        hint = " (for a constant slope use body.slope_deg)" if number else ""
        raise ValueError(f"expected a terrain profile: {TERRAIN_SYNTAX}; got {profile!r}{hint}")
    if not any(c.isdigit() for c in profile):
        raise ValueError(f"expected a terrain profile: {TERRAIN_SYNTAX}; got {profile!r} (terrains have no names)")
    pieces = []
    for k, part in enumerate(profile.split(",")):
        length, _, slope = part.partition(":")
        try:
            pieces.append((float(length), float(slope)))
        except ValueError:
            raise ValueError(
                f"expected a terrain profile: {TERRAIN_SYNTAX}; piece {k} of {profile!r} is {part!r}"
            ) from None
        if not (math.isfinite(pieces[-1][0]) and 0 < pieces[-1][0] <= 1000):
            raise ValueError(f"piece {k} of terrain {profile!r}: expected a length in (0, 1000] m; got {length!r}")
        _slope(pieces[-1][1], f"piece {k} of terrain {profile!r}")
    return pieces


class PlanarBipedParams(BodyParams):
    substeps: int = Field(10, ge=1, le=100, description="physics steps per control tick")
    motor_gain: float = Field(0.15, gt=0, description="K: stall torque per volt, N m / V")
    back_emf: float = Field(0.4, ge=0, description="k_e: V s / rad")
    resistance: float = Field(4.0, gt=0, description="R: motor winding resistance, ohm")
    trunk_stiffness: float = Field(8.0, ge=0, description="boom: trunk pitch spring, N m / rad")
    trunk_damping: float = Field(0.2, ge=0, description="boom: trunk pitch damper, N m s / rad")
    friction: float = Field(0.9, ge=0)
    min_distance: float = Field(0.5, ge=0, description="m forward needed for a success")
    min_steps: int = Field(4, ge=0, description="steps needed for a success")
    finish_line: float = Field(1.5, gt=0, description="m: distance for the walking-efficiency speed (5.7)")
    initial_speed: float = Field(0.3, ge=0, le=2, description="m/s forward at the start")


class PlanarBiped(Body):
    """Planar RunBot-style biped (pymunk), DC-motor hips and knees, trunk held by a boom spring."""

    Params = PlanarBipedParams
    SENSORS = SENSORS
    COMMANDS = COMMANDS
    TRIAL_PARAMS = ("slope_deg", "terrain")

    # ------------------------------------------------------------------ world
    def start_trial(self, request: TrialRequest) -> None:
        p = self.params
        self.pieces = self._terrain(request.body_params)
        space = pymunk.Space()
        space.gravity = (0.0, -9.81)
        space.collision_slop = 0.001
        space.iterations = 20
        self.space = space
        self._build_ground()
        x0 = 0.2
        ground0 = self.ground_height(x0)
        hip_height = THIGH + SHANK + FOOT_R - 0.003
        hip = pymunk.Vec2d(x0, ground0 + GROUND_R + hip_height * 0.985)
        self.trunk = self._box(M_TRUNK, TRUNK_W, TRUNK_H, hip + (0, TRUNK_UP))
        # stance (left) leg slightly forward of vertical, swing (right) leg behind, knee flexed
        self.legs = []
        for hip_angle, knee_angle in (
            (math.radians(8), math.radians(-2)),
            (math.radians(-18), math.radians(-35)),
        ):
            self.legs.append(self._leg(hip, hip_angle, knee_angle))
        boom = pymunk.DampedRotarySpring(self.trunk, space.static_body, 0.0, p.trunk_stiffness, p.trunk_damping)
        space.add(boom)
        for b in space.bodies:
            b.velocity = (p.initial_speed, 0.0)
        self.joints = [
            (self.trunk, self.legs[0][0]),
            (self.trunk, self.legs[1][0]),
            (self.legs[0][0], self.legs[0][1]),
            (self.legs[1][0], self.legs[1][1]),
        ]
        self._batch_buffers()
        self.t = 0.0
        self.x_start = self.trunk.position.x
        self.energy = 0.0
        self.fell = False
        self.steps = 0
        self.contact = np.zeros(2)
        self._last_foot = -1
        self._voltage = np.zeros(4)
        # a logged trial keeps, every `_log_every` ticks, the tick, its sensor values, the voltages
        # and the links' x, y, angle (see log_trial); nothing else runs per tick
        self._tick = 0
        self._log: list[np.ndarray] | None = [] if self.logging else None
        self._log_every = rates_of(self.telemetry).sample_every(p.control_dt) if self.logging else 0
        self.trial_id = request.trial_id
        self._update_contacts()

    @classmethod
    def check_trial_param(cls, name: str, value) -> None:
        """Raise ValueError if ``value`` cannot be trial parameter ``name`` (``sfl check`` calls
        this for conditions and axis bounds, so a bad terrain fails before the run starts)."""
        if name == "terrain":
            parse_terrain(value)
        elif name == "slope_deg":
            _slope(value)

    def _terrain(self, body_params: dict) -> list[tuple[float, float]]:
        profile = body_params.get("terrain")
        if profile:
            pieces = []
            for part in str(profile).split(","):
                length, _, slope = part.partition(":")
                pieces.append((float(length), math.radians(float(slope))))
            return pieces
        return [(60.0, math.radians(float(body_params.get("slope_deg", 0.0))))]

    def _build_ground(self) -> None:
        xs, ys, slopes = [-2.0], [0.0], []
        first_slope = self.pieces[0][1]
        ys[0] = -2.0 * math.tan(first_slope)
        x, y = 0.0, 0.0
        xs.append(x)
        ys.append(y)
        slopes.append(first_slope)
        for length, slope in self.pieces:
            x += length * math.cos(slope)
            y += length * math.sin(slope)
            xs.append(x)
            ys.append(y)
            slopes.append(slope)
        last = self.pieces[-1][1]
        xs.append(x + 60.0)
        ys.append(y + 60.0 * math.tan(last))
        slopes.append(last)
        self.ground_x, self.ground_y = np.array(xs), np.array(ys)
        self.ground_slopes = np.array(slopes)
        for i in range(len(xs) - 1):
            seg = pymunk.Segment(self.space.static_body, (xs[i], ys[i]), (xs[i + 1], ys[i + 1]), GROUND_R)
            seg.friction = self.params.friction
            self.space.add(seg)

    def _batch_buffers(self) -> None:
        """Buffers for pymunk's batch API: the joint torques go to every body in one call per physics
        step, and the state comes back in one call per tick (property by property, these reads and
        writes were most of a trial's time). Rows follow the space's own body order."""
        ids = pymunk.batch.Buffer()
        pymunk.batch.get_space_bodies(self.space, pymunk.batch.BodyFields.BODY_ID, ids)
        order = {int(i): k for k, i in enumerate(np.frombuffer(ids.int_buf(), dtype=np.uintp))}
        (tl, sl), (tr, sr) = self.legs
        # rows of trunk, thigh_l, shank_l, thigh_r, shank_r in the batch buffers
        self._rows = np.array([order[b.id] for b in (self.trunk, tl, sl, tr, sr)])
        self._torques = np.zeros(len(order))
        self._torque_buffer = pymunk.batch.Buffer()
        self._torque_buffer.set_float_buf(self._torques)
        self._state_buffer = pymunk.batch.Buffer()
        self._read_state()

    #: per body: x, y (m), angle (rad), angular velocity (rad/s), in the batch API's order
    _STATE_FIELDS = (
        pymunk.batch.BodyFields.POSITION | pymunk.batch.BodyFields.ANGLE | pymunk.batch.BodyFields.ANGULAR_VELOCITY
    )

    def _read_state(self) -> None:
        """x, y, angle, angular velocity of trunk, thigh_l, shank_l, thigh_r, shank_r (rows), one call."""
        buffer = self._state_buffer
        buffer.clear()
        pymunk.batch.get_space_bodies(self.space, self._STATE_FIELDS, buffer)
        self._state = np.frombuffer(buffer.float_buf()).reshape(-1, 4)[self._rows]

    def ground_height(self, x: float) -> float:
        return float(np.interp(x, self.ground_x, self.ground_y))

    def ground_slope(self, x: float) -> float:
        i = int(np.clip(np.searchsorted(self.ground_x, x) - 1, 0, len(self.ground_slopes) - 1))
        return float(self.ground_slopes[i])

    def _box(self, mass: float, w: float, h: float, position) -> pymunk.Body:
        body = pymunk.Body(mass, pymunk.moment_for_box(mass, (w, h)))
        body.position = position
        shape = pymunk.Poly.create_box(body, (w, h))
        shape.filter = pymunk.ShapeFilter(group=1)
        self.space.add(body, shape)
        return body

    def _rod(self, mass: float, length: float, top, angle: float, foot: bool) -> pymunk.Body:
        body = pymunk.Body(mass, pymunk.moment_for_segment(mass, (0, length / 2), (0, -length / 2), 0.01))
        body.angle = angle
        body.position = pymunk.Vec2d(*top) + pymunk.Vec2d(0, -length / 2).rotated(angle)
        shapes = [pymunk.Segment(body, (0, length / 2), (0, -length / 2), 0.008)]
        if foot:
            shapes.append(pymunk.Circle(body, FOOT_R, (0, -length / 2)))
        for s in shapes:
            s.filter = pymunk.ShapeFilter(group=1)  # the robot does not collide with itself
            s.friction = self.params.friction
        self.space.add(body, *shapes)
        return body

    def _leg(self, hip, hip_angle: float, knee_angle: float):
        thigh = self._rod(M_THIGH, THIGH, hip, hip_angle, foot=False)
        knee = hip + pymunk.Vec2d(0, -THIGH).rotated(hip_angle)
        shank = self._rod(M_SHANK, SHANK, knee, hip_angle + knee_angle, foot=True)
        p = self.params
        damping = p.motor_gain * p.back_emf  # back-EMF acts as viscous damping K k_e
        self.space.add(
            pymunk.PivotJoint(self.trunk, thigh, hip),
            pymunk.PivotJoint(thigh, shank, knee),
            pymunk.RotaryLimitJoint(self.trunk, thigh, *HIP_LIMITS),
            pymunk.RotaryLimitJoint(thigh, shank, *KNEE_LIMITS),
            pymunk.DampedRotarySpring(self.trunk, thigh, 0.0, 0.0, damping),
            pymunk.DampedRotarySpring(thigh, shank, 0.0, 0.0, damping),
        )
        return thigh, shank

    # ------------------------------------------------------------------ sensing
    def _foot(self, leg: int) -> pymunk.Vec2d:
        shank = self.legs[leg][1]
        return shank.local_to_world((0, -SHANK / 2))

    def _update_contacts(self) -> None:
        feet = [self._foot(0), self._foot(1)]
        xs = [feet[0].x, feet[1].x, self._state[0, 0]]  # both feet and the trunk (for sense())
        grounds = np.interp(xs[:2], self.ground_x, self.ground_y)
        slopes = self.ground_slopes[np.clip(np.searchsorted(self.ground_x, xs) - 1, 0, len(self.ground_slopes) - 1)]
        self._slope_under_trunk = float(slopes[2])
        for i in range(2):
            foot = feet[i]
            slope = float(slopes[i])
            clearance = (foot.y - float(grounds[i])) * math.cos(slope) - FOOT_R - GROUND_R
            on = clearance < (0.004 if self.contact[i] else 0.002)  # hysteresis
            if on and not self.contact[i] and i != self._last_foot:
                self.steps += 1  # a step: the other foot touches down
                self._last_foot = i
            self.contact[i] = 1.0 if on else 0.0

    def sense(self) -> np.ndarray:
        trunk, thigh_l, shank_l, thigh_r, shank_r = self._state[:, 2].tolist()  # angles, rad
        half_pi = math.pi / 2
        return np.array(
            [
                half_pi + thigh_l - trunk,
                half_pi + thigh_r - trunk,
                shank_l - thigh_l,
                shank_r - thigh_r,
                self.contact[0],
                self.contact[1],
                self._slope_under_trunk,
                trunk,
            ]
        )

    # ------------------------------------------------------------------ acting
    def actuate(self, command: np.ndarray) -> None:
        p = self.params
        voltage = np.clip(np.asarray(command, dtype=float), -MAX_VOLTAGE, MAX_VOLTAGE)
        h = p.control_dt / p.substeps
        # tau = K V on each joint, + on its child link and - on its parent (the -K k_e omega part is
        # the damper added at build time); the sums in the order a link's joints add them
        hip_l, hip_r, knee_l, knee_r = (p.motor_gain * voltage).tolist()
        torques, rows = self._torques, self._rows
        torques[rows] = (0.0 - hip_l - hip_r, 0.0 + hip_l - knee_l, 0.0 + knee_l, 0.0 + hip_r - knee_r, 0.0 + knee_r)
        space, buffer, set_bodies, fields = self.space, self._torque_buffer, pymunk.batch.set_space_bodies, _TORQUE
        for _ in range(p.substeps):
            set_bodies(space, fields, buffer)  # pymunk zeroes every torque after a step
            space.step(h)
        self._read_state()
        spin = self._state[:, 3]  # trunk, thigh_l, shank_l, thigh_r, shank_r, rad/s
        omega = spin[[1, 3, 2, 4]] - spin[[0, 0, 1, 3]]  # child - parent, joints as COMMANDS
        current = (voltage - p.back_emf * omega) / p.resistance
        self.energy += float(np.sum(p.resistance * current**2)) * p.control_dt  # (5.5)-(5.6)
        self.t += p.control_dt
        self._update_contacts()
        trunk_y, shank_l_y, shank_r_y = self._state[[0, 2, 4], 1].tolist()
        if trunk_y < shank_l_y or trunk_y < shank_r_y:
            self.fell = True  # trunk centre of mass below a shank's (§3.4.3)
        if self._log is not None and self._tick % self._log_every == 0:
            self._log.append(np.concatenate(((self._tick,), self.sense(), voltage, self._state[:, :3].ravel())))
        self._tick += 1

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
    }

    def outcome(self) -> tuple[bool, float, dict]:
        p = self.params
        distance = self.trunk.position.x - self.x_start
        velocity = distance / self.t if self.t > 0 else 0.0
        success = (not self.fell) and distance >= p.min_distance and self.steps >= p.min_steps
        mass = M_TRUNK + 2 * (M_THIGH + M_SHANK)
        # walking efficiency (5.7)-(5.8): kinetic energy at the average speed over the energy spent
        quality = walking_efficiency(mass, velocity, self.energy) if success else 0.0
        metrics = {
            "distance": distance,
            "velocity": velocity,
            "steps": self.steps,
            "time": self.t,
            "energy": self.energy,
            "fell": self.fell,
        }
        return success, quality, metrics

    # ------------------------------------------------------------------ recording
    def log_trial(self, trial_id: int) -> None:
        """A logged trial as telemetry on ``sim_time`` (trial k starts at k x duration): joint angles
        (deg), motor voltages (V) and foot contacts at ``rates.signals_hz``, the walker's links as
        2-D line strips at ``rates.pictures_hz``, and the ground under its path."""
        if not self._log:
            return
        p, sink = self.params, self.telemetry
        rates = rates_of(sink)
        log = np.stack(self._log)
        ticks = log[:, 0].astype(np.int64)
        times = trial_id * p.duration + p.control_dt * (ticks + 1)  # the state after tick i
        sensors, voltage, links = log[:, 1:9], log[:, 9:13], log[:, 13:].reshape(-1, 5, 3)
        shown = ticks % rates.signal_every(p.control_dt) == 0
        for j, signal in enumerate(SENSORS[:4]):
            sink.emit(series(f"joints/{signal.name}", trial_id, times[shown], np.degrees(sensors[shown, j]), "deg"))
        for j, signal in enumerate(COMMANDS):  # motor voltages (3.6): the motor neurons' net output
            sink.emit(series(f"motors/{signal.name}", trial_id, times[shown], voltage[shown, j], "V"))
        for j, side in ((4, "left"), (5, "right")):
            sink.emit(series(f"contacts/{side}", trial_id, times[shown], sensors[shown, j]))
        pictured = ticks % rates.picture_every(p.control_dt) == 0
        points = _walker_points(links[pictured])
        strips = points[:, _WALKER_STRIPS].reshape(-1, _WALKER_STRIPS.shape[1], 2)  # (pictures x 3, 3, 2)
        sink.emit(
            Strips2D("walker", trial_id, times[pictured], strips, len(_WALKER_STRIPS), _WALKER_COLORS, follow=True)
        )
        hip_x = points[:, 1, 0]
        gx = np.linspace(float(hip_x.min()) - 0.5, float(hip_x.max()) + 0.5, 60)
        ground = np.column_stack([gx, np.interp(gx, self.ground_x, self.ground_y)])
        sink.emit(Strips2D("ground", trial_id, np.array([trial_id * p.duration]), [ground], 1, _GROUND_COLOR, 0.004))

    def close(self) -> None:
        self.space = None


def _walker_points(links: np.ndarray) -> np.ndarray:
    """(frames, 6, 2) points [trunk, hip, left knee, left foot, right knee, right foot] from the
    links' (frames, 5, 3) x, y, angle [trunk, thigh_l, shank_l, thigh_r, shank_r]: a link's point
    at (0, -d) in its own frame is at (x + d sin a, y - d cos a)."""

    def below(link: int, d: float) -> np.ndarray:
        x, y, a = links[:, link, 0], links[:, link, 1], links[:, link, 2]
        return np.stack([x + d * np.sin(a), y - d * np.cos(a)], axis=1)

    trunk = links[:, 0, :2]
    return np.stack(
        [trunk, below(0, TRUNK_UP), below(1, THIGH / 2), below(2, SHANK / 2), below(3, THIGH / 2), below(4, SHANK / 2)],
        axis=1,
    )
