"""A trial's start (thesis §5.7, L1737), as part of ``CPGNetwork`` (network.py).

At a trial's first tick: ``start_from_pose`` (the named joints' command starts at the measured pose), ``start_slope``
(the named joints' command starts at their calibrated pose shifted by the slope the trial starts on: "only ankle pitch
joint initialized from stance position", L1737), and the motor neurons' drive at rest, which the group gain multipliers
scale the drive about (gains.py). Over its first seconds, the circuit's ``start_ramp``: alpha_MLR of (4.9) grows from 0
(``_update_pattern_formation`` in network.py reads the ramp's share of the way).
"""

from __future__ import annotations

import numpy as np


class TrialStart:
    """``CPGNetwork``'s start of a trial: the first tick's commands, the start ramp."""

    def _build_trial_start(self, circuit) -> None:
        """The joints whose command starts at the measured pose, and those whose start pose follows the slope."""
        self._start_from_pose = [
            (circuit.joint_index(name), circuit.inputs.index(circuit.joints[circuit.joint_index(name)].angle_input))
            for name in circuit.start_from_pose
        ]
        self._start_slope_joints = [
            (circuit.joint_index(name), circuit.joints[circuit.joint_index(name)].pose0, per_slope)
            for name, per_slope in circuit.start_slope.items()
        ]

    def _reset_trial_start(self) -> None:
        """A trial's start: the circuit's ``start_ramp``, no start slope."""
        self._set_ramp(self.circuit.start_ramp)
        self._start_slope: float | None = None  # rad: the slope this trial starts on, if a trial says (set_start_slope)

    def set_start_ramp(self, seconds: float) -> None:
        """alpha_MLR grows from 0 over this trial's first ``seconds`` (0: at once); before its first tick."""
        if not (np.isfinite(seconds) and seconds >= 0):
            raise ValueError(f"start_ramp: expected a time in s >= 0; got {seconds!r}")
        if self.tick:
            raise ValueError("start_ramp: set it before the trial's first tick")
        self._set_ramp(float(seconds))
        self._update_pattern_formation()

    def _set_ramp(self, seconds: float) -> None:
        self.start_ramp = seconds  # s
        self._ramp_share = 0.0 if seconds > 0 else 1.0  # alpha_MLR's share of the way (1: no ramp, or it is over)

    def set_start_slope(self, slope: float) -> None:
        """This trial starts on ground sloping ``slope`` rad (uphill +): at its first tick the circuit's ``start_slope``
        joints command their calibrated start pose shifted by it (``reset`` forgets it)."""
        self._start_slope = float(slope)

    def _first_tick(self, phi: np.ndarray, rho: np.ndarray) -> None:
        """A trial's first tick: ``start_from_pose`` (the named joints' command starts at the measured pose),
        ``start_slope`` (the named joints' command starts at their calibrated pose shifted by the slope), and the
        motor neurons' drive at rest on this frame, which the group gain multipliers scale the drive about."""
        every = np.ones(self.batch, dtype=bool)
        if self._start_from_pose:
            self._hold_at_switch.extend((every, j, phi[:, source].copy()) for j, source in self._start_from_pose)
        if self._start_slope is not None:  # circuit start_slope: the calibrated start pose shifted by the slope
            slope = self._start_slope
            self._hold_at_switch.extend(
                (every, j, np.full(self.batch, pose0 + k * slope)) for j, pose0, k in self._start_slope_joints
            )
        if self.gain_groups and self.circuit.command == "position":
            self._rest_drive = self._drive_at_rest(rho)
            self.theta0 += (self._circuit_gain - self._gain) * self._rest_drive  # multipliers set before the trial

    def _ramp_tick(self) -> None:
        """The circuit's start_ramp at the tick's end: alpha_MLR's share of the way, and the PF constants with it."""
        self._ramp_share = min(1.0, self.time / self.start_ramp)
        self._update_pattern_formation()
