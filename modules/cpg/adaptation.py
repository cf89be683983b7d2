"""The ankles' centres of oscillation following the slope each foot senses (issue 29; circuit key ``ankle_adaptation``).

The thesis adjusts "the center of oscillation of each joint" to walk from flat onto sloped terrain (L1417), starts a
trial on a slope with "only ankle pitch joint initialized from stance position" (L1737), and uses the inertial sensor
"to adjust the center of oscillation of ankle joints" while walking (L1764). It does not say how. Here each foot senses
the ground under it and its ankle's centre follows (``circuit.AnkleAdaptation``, whose docstring has the rule):

- the sole's pitch in the world is the torso's pitch (the inertial sensor) plus the leg's pitch joints (hip, knee,
  ankle pitch turn about the same axis); when the heel and the toe both press (the contact neurons GB and GF, L1345)
  the sole lies on the ground, so minus that pitch is the slope under it (+ = uphill);
- each foot's estimate follows its flat-stance readings (first order, ``rate``); a foot not lying flat (in the air, or
  on its heel or toe) aims at the ground last sensed by a foot lying flat, so that it lands on the slope the other
  stands on, and does not fall back to its own older estimate while it rolls onto the new ground;
- each ankle's centre (its theta_0) moves toward ``per_slope`` x the aimed slope, at most ``speed`` rad/s.

At a trial's first tick the estimate is the slope the start pose shows, and the centre takes it at once: a gait started
on a ramp and the same gait reached by walking onto the ramp then have the same ankle centres by construction (issue
29's item 1). Plain numpy over the network's batch copies.

``AnkleAdaptation`` is this seam's part of ``CPGNetwork`` (network.py): building it, switching it per trial, reading it.
"""

from __future__ import annotations

import numpy as np

from .circuit import Circuit


class AnkleCentres:
    """The circuit's ``ankle_adaptation`` for ``batch`` copies: per foot, its slope estimate and its ankle's centre
    shift (rad, added to that ankle's theta_0)."""

    def __init__(self, circuit: Circuit, batch: int) -> None:
        spec = circuit.ankle_adaptation
        assert spec is not None
        self.spec, self.batch = spec, batch
        names = [s.name for s in circuit.sensory_neurons]
        self.joints = np.array([circuit.joint_index(name) for name in spec.feet], dtype=int)
        self.heel = np.array([names.index(foot.heel) for foot in spec.feet.values()], dtype=int)
        self.toe = np.array([names.index(foot.toe) for foot in spec.feet.values()], dtype=int)
        self.pitch = circuit.inputs.index(spec.pitch_input)
        #: (inputs, feet): 1 where an input is part of a foot's chain, so that every sole's pitch is one product
        self.chain = np.zeros((len(circuit.inputs), len(spec.feet)))
        for f, foot in enumerate(spec.feet.values()):
            for name in foot.chain:
                self.chain[circuit.inputs.index(name), f] += 1.0
        self.reset()

    def reset(self) -> None:
        """A trial's start: nothing sensed yet, no shift."""
        #: (batch, feet): each foot's slope estimate, rad, + = uphill (None before the first tick)
        self.estimate: np.ndarray | None = None
        #: (batch, feet): each ankle's centre shift, rad
        self.centre = np.zeros((self.batch, len(self.joints)))
        #: (batch, feet): the slope each foot aimed at on the last tick, rad
        self.aim = np.zeros((self.batch, len(self.joints)))
        #: (batch,): the slope last sensed by a foot in flat stance (the feet's mean when both are), rad
        self.latest = np.zeros(self.batch)

    def ground(self, phi: np.ndarray) -> np.ndarray:
        """(batch, feet): minus each sole's pitch in the world, rad: the slope under it when it lies on the ground."""
        return -(phi[:, self.pitch : self.pitch + 1] + phi @ self.chain)

    def step(self, phi: np.ndarray, rho: np.ndarray, dt: float) -> np.ndarray:
        """One control tick (``phi``: the raw inputs, ``rho``: the sensory neurons, (batch, ...)); returns the change of
        each ankle's centre, (batch, feet), to add to its theta_0."""
        spec = self.spec
        reading = self.ground(phi)
        heel, toe = rho[:, self.heel], rho[:, self.toe]
        flat = (heel >= spec.stance) & (toe >= spec.stance)
        first = self.estimate is None
        if first:  # the start pose shows the slope it stands on
            self.estimate = reading.copy()
            self.latest = reading.mean(axis=1)
        else:
            self.estimate += np.where(flat, (reading - self.estimate) * min(1.0, spec.rate * dt), 0.0)
        standing = flat.sum(axis=1)
        if standing.any():  # the ground last sensed: the feet in flat stance now
            mean = (self.estimate * flat).sum(axis=1) / np.maximum(standing, 1)
            self.latest = np.where(standing > 0, mean, self.latest)
        aim = self.estimate.copy()
        if spec.share:  # a foot not lying flat aims at the ground last sensed (it lands where the other stands)
            aim = np.where(flat, aim, self.latest[:, None])
        np.clip(aim, -spec.limit, spec.limit, out=aim)
        self.aim = aim
        want = np.where(aim > 0, spec.per_slope_up, spec.per_slope_down) * aim
        change = want - self.centre
        if not first:
            step = spec.speed * dt
            np.clip(change, -step, step, out=change)
        self.centre += change
        return change


class AnkleAdaptation:
    """``CPGNetwork``'s ankle adaptation (``AnkleCentres`` above): switching it per trial, and reading it."""

    def _build_ankles(self, circuit) -> None:
        """Each ankle's centre following the slope its foot senses (``AnkleCentres``), if the circuit has them."""
        self._ankles = AnkleCentres(circuit, self.batch) if circuit.ankle_adaptation is not None else None

    def _reset_ankles(self) -> None:
        """A trial's start: adapting as the circuit says, nothing sensed yet."""
        adaptation = self.circuit.ankle_adaptation
        self.ankle_adaptation = bool(adaptation is not None and adaptation.enabled)  # on this trial (issue 29)
        if self._ankles is not None:
            self._ankles.reset()

    def set_ankle_adaptation(self, on: bool) -> None:
        """The ankles' centres follow the sensed slope this trial (``ankle_adaptation``; ``reset`` restores the
        circuit's ``enabled``)."""
        if on and self._ankles is None:
            raise ValueError(f"ankle_adaptation: circuit {self.circuit.name} has none (circuit key `ankle_adaptation`)")
        self.ankle_adaptation = bool(on)

    @property
    def slope_estimate(self) -> np.ndarray:
        """Each adapted foot's slope estimate, rad, + = uphill, (feet,) or (batch, feet); zeros before the first tick
        or without an adaptation (issue 29)."""
        out = self.slope_estimate_all()
        return out if self.batched else out[0]

    def slope_estimate_all(self) -> np.ndarray:
        """``slope_estimate`` with the batch axis always."""
        a = self._ankles
        if a is None:
            return np.zeros((self.batch, 0))
        return a.estimate.copy() if a.estimate is not None else np.zeros((self.batch, len(a.joints)))

    @property
    def ankle_centre(self) -> np.ndarray:
        """Each adapted ankle's centre shift (added to its theta_0), rad, (feet,) or (batch, feet)."""
        out = self.ankle_centre_all()
        return out if self.batched else out[0]

    def ankle_centre_all(self) -> np.ndarray:
        """``ankle_centre`` with the batch axis always."""
        a = self._ankles
        return a.centre.copy() if a is not None else np.zeros((self.batch, 0))
