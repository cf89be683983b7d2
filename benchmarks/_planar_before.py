"""The planar biped as it stepped before its hot path was batched: the baseline of
``benchmarks/planar.py``'s (b0), kept so that both are measured side by side in one run.

Every pymunk property is read and written one by one, as the body did until 2026-11-23: joint
torques per body per physics step, angles and angular velocities per tick, and the ground under
each foot and the trunk looked up one scalar at a time.
"""

from __future__ import annotations

import math

import numpy as np

from sfl_brain.bodies.planar_biped import FOOT_R, GROUND_R, PlanarBiped


class PlanarBipedBefore(PlanarBiped):
    def _update_contacts(self) -> None:
        for i in range(2):
            foot = self._foot(i)
            slope = self.ground_slope(foot.x)
            clearance = (foot.y - self.ground_height(foot.x)) * math.cos(slope) - FOOT_R - GROUND_R
            on = clearance < (0.004 if self.contact[i] else 0.002)
            if on and not self.contact[i] and i != self._last_foot:
                self.steps += 1
                self._last_foot = i
            self.contact[i] = 1.0 if on else 0.0

    def sense(self) -> np.ndarray:
        trunk = self.trunk
        (tl, sl), (tr, sr) = self.legs
        half_pi = math.pi / 2
        return np.array(
            [
                half_pi + tl.angle - trunk.angle,
                half_pi + tr.angle - trunk.angle,
                sl.angle - tl.angle,
                sr.angle - tr.angle,
                self.contact[0],
                self.contact[1],
                self.ground_slope(trunk.position.x),
                trunk.angle,
            ]
        )

    def actuate(self, command: np.ndarray) -> None:
        p = self.params
        voltage = np.clip(np.asarray(command, dtype=float), -12.0, 12.0)
        h = p.control_dt / p.substeps
        for _ in range(p.substeps):
            for (parent, child), v in zip(self.joints, voltage, strict=True):
                tau = p.motor_gain * v
                child.torque += tau
                parent.torque -= tau
            self.space.step(h)
        omega = np.array([c.angular_velocity - a.angular_velocity for a, c in self.joints])
        current = (voltage - p.back_emf * omega) / p.resistance
        self.energy += float(np.sum(p.resistance * current**2)) * p.control_dt
        self.t += p.control_dt
        self._update_contacts()
        trunk_y = self.trunk.position.y
        if trunk_y < self.legs[0][1].position.y or trunk_y < self.legs[1][1].position.y:
            self.fell = True
        if self._log is not None and self._tick % self._log_every == 0:
            self._read_state()  # the links' x, y, angle for the picture (a logged trial only)
            self._log.append(np.concatenate(((self._tick,), self.sense(), voltage, self._state[:, :3].ravel())))
        self._tick += 1
