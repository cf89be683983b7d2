"""The motor neurons' gains in groups (thesis §5.6.1, L1631, Fig. 5.9; digest §7.8), as part of ``CPGNetwork``.

Chapter 5 learns the motor-neuron gains w1 (pitch) and w2 (roll) (Fig. 5.9 caption): the circuit's ``gain_groups`` name
the joints of each group, and ``set_gain_multiplier`` scales every gain G of a group by one number (1 = the calibrated
gait). The thesis has one G per group (§7.8); our gait is calibrated with one G per joint, so a common multiplier is the
faithful reading of "one G for all pitch joints, one for both roll joints". A position command is scaled about the
drive at rest (``set_gain_multiplier``), so that the calibrated standing pose stays where it is.
"""

from __future__ import annotations

import numpy as np

from .equations import E, F


class GainGroups:
    """``CPGNetwork``'s group gain multipliers (w1 pitch, w2 roll) and the drive at rest they scale about."""

    def _build_gains(self, circuit) -> None:
        """The calibrated gain per joint, and the joints of each group."""
        self._circuit_gain = np.array([j.gain for j in circuit.joints])  # the calibrated G per joint
        #: group name (pitch, roll) -> its joints' indices (circuit ``gain_groups``; ch. 5's w1, w2)
        self.gain_groups = {
            group: np.array([circuit.joint_index(name) for name in names], dtype=int)
            for group, names in circuit.gain_groups.items()
        }

    def _reset_gains(self) -> None:
        """A trial's start: every multiplier 1 (the circuit's gains), no drive at rest yet."""
        b = self.batch
        self._gain = np.tile(self._circuit_gain, (b, 1))
        #: group -> its gain multiplier per batch copy (1 = the circuit's gains)
        self.gain_multipliers = {group: np.ones(b) for group in self.gain_groups}
        self._rest_drive: np.ndarray | None = None  # MN_E - MN_F at rest on the first frame (set_gain_multiplier)

    def set_gain_multiplier(self, group: str, value) -> None:
        """Ch. 5's learnt MN gain of a group (w1 pitch, w2 roll, L1631): every joint of ``gain_groups[group]`` gets its
        circuit gain times ``value`` (one number or one per batch copy; 1 = the calibrated gait) until ``reset``.

        A position command scales the motor neurons' drive about its value at rest: theta_cmd = theta_0 + G D_rest +
        value G (D - D_rest), D = MN_E - MN_F, D_rest = D with every RG at rest on the trial's first frame (the
        reflexes' offset; ``_drive_at_rest``). So the command at rest is the calibrated one (the circuit's theta_0 is
        calibrated so that it is the standing pose) whatever the multiplier, and the multiplier scales the oscillation
        only, as G does in the author's code, whose reflexes are off (D_rest = 0, digest §5). Literally (theta_0 +
        value G D) it would also move every joint's resting angle by (value - 1) G D_rest: the knees by 0.5 rad at
        1.5, and 0 would collapse the robot instead of standing it. A voltage command is scaled as it is."""
        self._check_gain_group(group, f"gain_{group}")
        values = np.broadcast_to(np.asarray(value, dtype=float), (self.batch,))
        self._set_gains(group, values, np.arange(self.batch))

    def _check_gain_group(self, group: str, key: str) -> None:
        if group not in self.gain_groups:
            raise ValueError(
                f"{key}: expected a gain group of circuit {self.circuit.name} (gain_groups "
                f"{list(self.gain_groups)}); it has no {group!r}"
            )

    def _set_gains(self, group: str, values: np.ndarray, rows: np.ndarray) -> None:
        """The group's multipliers of the copies ``rows`` := ``values`` (one per such copy), and their gains."""
        cols = self.gain_groups[group]
        cells = np.ix_(rows, cols)
        gain = values[:, None] * self._circuit_gain[cols]
        if self._rest_drive is not None:  # mid-trial: the drive at rest keeps its command (see set_gain_multiplier)
            self.theta0[cells] += (self._gain[cells] - gain) * self._rest_drive[cells]
        self.gain_multipliers[group][rows] = values
        self._gain[cells] = gain

    @property
    def gain(self) -> np.ndarray:
        """G per joint (M of (3.6) or G of theta_0 + G (MN_E - MN_F)) after the group multipliers, (joints,) or (batch,
        joints)."""
        return self._gain if self.batched else self._gain[0]

    def _drive_at_rest(self, rho: np.ndarray) -> np.ndarray:
        """MN_E - MN_F per joint, (batch, joints), with every RG at rest (V = 0) and the sensory neurons ``rho``: what
        the reflexes alone make the motor neurons say: (4.9)-(4.12) with the RG term 0 (``_static_layers``)."""
        _, mn = self._static_layers(rho, 0.0)
        return mn[:, E::2] - mn[:, F::2]
