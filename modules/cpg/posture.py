"""The torso held about 10 deg from the vertical (thesis §5.8, L1764; digest §7.18), as part of ``CPGNetwork``.

The thesis holds the torso with the inertial sensor (L1764) and does not say how. Here the circuit's ``posture``
(``Posture`` in circuit.py) is a slow integral term on the named joints' theta_0, applied at the end of each tick: each
moves by gain x sign x (input - target) x dt (the input averaged over its last ``window``, one gait cycle), its
accumulated shift kept within +-limit; ``set_posture_gain`` sets the gain per trial. While the term is on, the sensory
neurons of ``relative_sensors`` (4.13) measure from the held lean (issue 29).
"""

from __future__ import annotations

import numpy as np


class Posture:
    """``CPGNetwork``'s posture term (L1764, §7.18): its gain, the thresholds it moves, its shift of theta_0."""

    def _build_posture(self, circuit) -> None:
        """The posture's input, joints and their signs, and the sensory neurons that measure from its target."""
        posture = circuit.posture  # the torso held near an angle (L1764, §7.18): (input, joints, signs, target, limit)
        self._relative_sensors = np.zeros(0, dtype=int)
        if posture is not None:
            self._posture_input = circuit.inputs.index(posture.input)
            self._posture_joints = np.array([circuit.joint_index(name) for name in posture.joints], dtype=int)
            self._posture_signs = np.array([float(sign) for sign in posture.joints.values()])
            self._relative_sensors = np.array([self.sensor_names.index(n) for n in posture.relative_sensors], dtype=int)

    def _reset_posture(self) -> None:
        """A trial's start: the circuit's gain, no shift, no window of the input yet."""
        self.posture_gain = self.circuit.posture.gain if self.circuit.posture is not None else 0.0  # 1/s
        self._update_sensor_thresholds()
        posture = self.circuit.posture
        self._posture_shift = np.zeros((self.batch, 0 if posture is None else len(posture.joints)))  # rad, L1764
        # the posture input's last window of values (posture.window; allocated at its first tick), a running sum
        self._posture_values: np.ndarray | None = None
        self._posture_sum, self._posture_count = np.zeros(self.batch), 0

    def set_posture_gain(self, gain: float) -> None:
        """The posture term's gain, 1/s, until ``reset`` (which restores the circuit's); 0 = off (L1764, §7.18)."""
        if self.circuit.posture is None:
            raise ValueError(f"posture_gain: circuit {self.circuit.name} has no posture (circuit key `posture`)")
        if not (np.isfinite(gain) and gain >= 0):
            raise ValueError(f"posture_gain: expected a gain in 1/s >= 0; got {gain!r}")
        self.posture_gain = float(gain)
        self._update_sensor_thresholds()

    def _update_sensor_thresholds(self) -> None:
        """The sensory neurons' thresholds (4.13): the file's, those of ``posture.relative_sensors`` moved by the
        posture's target while the posture term is on (a fall from the held lean, issue 29)."""
        self._sensor_theta = self._sensor_theta_file.copy()
        if self.posture_gain and len(self._relative_sensors):
            self._sensor_theta[self._relative_sensors] += self.circuit.posture.target

    @property
    def posture_shift(self) -> np.ndarray:
        """The posture term's accumulated shift of its joints' theta_0, rad, in ``posture.joints`` order ((batch, n)
        when batched); empty without a posture."""
        return self._posture_shift.copy() if self.batched else self._posture_shift[0].copy()

    def _posture(self, phi: np.ndarray, control_dt: float) -> None:
        """The torso held near its target (L1764, §7.18; circuit ``posture``): each of the posture's joints' theta_0
        moves by gain sign (input - target) dt this tick, its accumulated shift kept within +-limit."""
        posture, old = self.circuit.posture, self._posture_shift
        value = phi[:, self._posture_input]
        if posture.window > 0:  # the input's mean over the last window (one gait cycle: its swing averages out)
            if self._posture_values is None:
                self._posture_values = np.zeros((self.batch, max(1, int(round(posture.window / control_dt)))))
            n = self._posture_values.shape[1]
            slot = self.tick % n
            self._posture_sum += value - self._posture_values[:, slot]
            self._posture_values[:, slot] = value
            self._posture_count = min(self._posture_count + 1, n)
            value = self._posture_sum / self._posture_count
        lean = value - posture.target  # rad, + = past the target in the input's + direction
        shift = old + np.multiply.outer(lean * (self.posture_gain * control_dt), self._posture_signs)
        np.minimum(np.maximum(shift, -posture.limit, out=shift), posture.limit, out=shift)  # np.clip, cheaper
        self.theta0[:, self._posture_joints] += shift - old
        self._posture_shift = shift
