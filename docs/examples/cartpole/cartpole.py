"""A cart-pole: a pole hinged on a cart that runs on a straight, level track (Barto, Sutton &
Anderson 1983, with the equations of motion as corrected by Florian 2007; frictionless).

The controller pushes the cart with a horizontal force (N, clipped to +-10 N). The pole angle is
0 upright and positive leaning toward +x; the cart position is 0 at the middle of the track.
Physics: semi-implicit Euler, ``substeps`` steps per control tick.

A trial starts with the pole tilted by ``tilt_deg`` (a trial parameter, so a scenario can set it
as a condition or learn over it) and fails when the pole leans past 12 deg or the cart runs more
than 2.4 m from the middle. A success is a pole still up after ``duration`` s; its quality eta is
1 / (1 + F_rms / 1 N), so gentle balancing (a small root-mean-square force) ranks above rough.
"""

from __future__ import annotations

import math

import numpy as np
from pydantic import Field

from sfl_brain.body import Body, BodyParams
from sfl_brain.messages import TrialRequest
from sfl_brain.signals import Signal
from sfl_brain.telemetry import Strips2D, rates_of, series

G = 9.81  # m/s^2
TRACK = 2.4  # m either side of the middle
FALL = math.radians(12.0)  # rad: the pole has fallen past this
MAX_FORCE = 10.0  # N
MAX_SPEED = 15.0  # m/s: the cart cannot reach more than this within the track at MAX_FORCE
MAX_SPIN = 10.0  # rad/s: nor the pole this between +-FALL
MAX_TILT = 10.0  # deg: the steepest start a trial may ask for


class CartPoleParams(BodyParams):
    duration: float = Field(5.0, gt=0, le=600, description="trial length, s of simulated time")
    cart_mass: float = Field(1.0, gt=0, description="kg")
    pole_mass: float = Field(0.1, gt=0, description="kg, spread evenly along the pole")
    half_length: float = Field(0.5, gt=0, description="m, hinge to the pole's centre of mass")
    substeps: int = Field(5, ge=1, le=100, description="physics steps per control tick")
    tilt_deg: float = Field(6.0, ge=-MAX_TILT, le=MAX_TILT, description="deg: the pole's start, if a trial sets none")


class CartPole(Body):
    """A pole balanced on a cart pushed by a horizontal force (frictionless, on a 4.8-m track)."""

    Params = CartPoleParams
    SENSORS = (
        Signal("cart_x", "m", -TRACK, TRACK, "cart position, 0 = middle of the track"),
        Signal("cart_v", "m/s", -MAX_SPEED, MAX_SPEED, "cart velocity"),
        Signal("angle", "rad", -FALL, FALL, "pole angle, 0 = upright, positive = leaning toward +x"),
        Signal("spin", "rad/s", -MAX_SPIN, MAX_SPIN, "pole angular velocity"),
    )
    COMMANDS = (Signal("force", "N", -MAX_FORCE, MAX_FORCE, "horizontal push on the cart, clipped"),)
    TRIAL_PARAMS = ("tilt_deg",)
    METRICS = {"time_up": "s", "rms_force": "N", "fell": "", "off_track": ""}  # outcome()'s metrics and their units

    @classmethod
    def check_trial_param(cls, name: str, value) -> None:
        """``sfl check`` calls this for each condition and axis bound that targets ``body.<name>``."""
        if name == "tilt_deg" and not abs(value) <= MAX_TILT:
            raise ValueError(f"expected a starting tilt within +-{MAX_TILT:g} deg; got {value!r}")

    def start_trial(self, request: TrialRequest) -> None:
        tilt = float(request.body_params.get("tilt_deg", self.params.tilt_deg))
        self.state = np.array([0.0, 0.0, math.radians(tilt), 0.0])  # cart_x, cart_v, angle, spin
        self.ticks, self.t = 0, 0.0
        self.effort = 0.0  # integral of force^2 dt, N^2 s
        self.trace = [] if self.logging else None  # (t, cart_x, angle, force) of a logged trial

    def sense(self) -> np.ndarray:
        return self.state.copy()

    def actuate(self, command: np.ndarray) -> None:
        p = self.params
        force = min(max(float(command[0]), -MAX_FORCE), MAX_FORCE)
        total = p.cart_mass + p.pole_mass
        h = p.control_dt / p.substeps
        x, v, angle, spin = self.state.tolist()
        for _ in range(p.substeps):
            sin, cos = math.sin(angle), math.cos(angle)
            push = (force + p.pole_mass * p.half_length * spin**2 * sin) / total
            spin_rate = (G * sin - cos * push) / (p.half_length * (4 / 3 - p.pole_mass * cos**2 / total))
            v += h * (push - p.pole_mass * p.half_length * spin_rate * cos / total)
            spin += h * spin_rate
            x += h * v  # semi-implicit: positions move with the new velocities
            angle += h * spin
        self.state = np.array([x, v, angle, spin])
        self.ticks += 1
        self.t = self.ticks * p.control_dt  # s since the start (a count: no rounding drift)
        self.effort += force**2 * p.control_dt
        if self.trace is not None:
            self.trace.append((self.t, x, angle, force))

    @property
    def fell(self) -> bool:
        return bool(abs(self.state[2]) > FALL)

    @property
    def off_track(self) -> bool:
        return bool(abs(self.state[0]) > TRACK)

    @property
    def done(self) -> bool:
        return self.fell or self.off_track or self.t >= self.params.duration - 1e-9

    def outcome(self) -> tuple[bool, float, dict]:
        success = not (self.fell or self.off_track)
        rms_force = math.sqrt(self.effort / self.t) if self.t > 0 else 0.0
        quality = 1.0 / (1.0 + rms_force) if success else 0.0
        metrics = {"time_up": self.t, "rms_force": rms_force, "fell": self.fell, "off_track": self.off_track}
        return success, quality, metrics

    def log_trial(self, trial_id: int) -> None:
        """The cart's position, the pole's angle and the force as scalars, and the cart and pole as line
        strips, at the rates the telemetry sink asks for (the base class marks the trial's start and end).
        Called only on a logged trial, so ``self.telemetry`` is there."""
        if not self.trace:
            return
        rates, dt = rates_of(self.telemetry), self.params.control_dt
        t, x, angle, force = np.array(self.trace).T
        times = trial_id * self.params.duration + t  # trial k starts at k x duration on sim_time
        sampled = slice(None, None, rates.signal_every(dt))
        self.telemetry.emit(series("cart_x", trial_id, times[sampled], x[sampled], "m"))
        self.telemetry.emit(series("angle", trial_id, times[sampled], np.degrees(angle[sampled]), "deg"))
        self.telemetry.emit(series("force", trial_id, times[sampled], force[sampled], "N"))
        shown = range(0, len(t), rates.picture_every(dt))
        tip = 2 * self.params.half_length
        strips = []
        for k in shown:  # per picture: the cart (a box), the pole (a line from the hinge), the track
            cart = np.array([[-0.2, 0.0], [0.2, 0.0], [0.2, 0.1], [-0.2, 0.1], [-0.2, 0.0]]) + (x[k], 0.0)
            pole = np.array([[x[k], 0.1], [x[k] + tip * math.sin(angle[k]), 0.1 + tip * math.cos(angle[k])]])
            strips += [cart, pole, np.array([[-TRACK, 0.0], [TRACK, 0.0]])]
        colors = np.array([(40, 110, 220), (230, 140, 30), (120, 100, 80)], dtype=np.uint8)
        self.telemetry.emit(Strips2D("picture", trial_id, times[list(shown)], strips, per_frame=3, colors=colors))
