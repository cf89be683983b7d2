"""Pattern switching (thesis §4.4.4.2, L1284-1325, and §4.4.5.3, L1428-1440; digest §7.11), as part of ``CPGNetwork``
(network.py): the circuit's switches, their triggers, and the switch itself.

- §7.11: pattern switching = new (sigma_s, sigma_f), V = q = 0, then a kick of +I (F) / -I (E) for 0.2 s. A
  position-commanded joint's theta_0 is set so that its command stays at the measured angle (``theta0:
  continuous``, the default: the joint goes on from where it is). The author's later (2017) scripts set theta_0 :=
  the measured angle instead (digest §5, last bullet; ``theta0: angle``): their circuit has its reflexes off, and in
  ours, whose reflexes hold MN_E - MN_F away from 0, that makes the command jump by the reflexes' offset. A kick's
  sign is given (the direction of the switch, L1437), or (``kick_direction: motion``, issue 23's E4.4) follows the
  way the joint moves.
- A switch may silence the couplings between named joint pairs (L1311).
- Triggers, checked once per control tick: a time ``at``, an input level ``above``, an input rate ``rate_above``.
"""

from __future__ import annotations

import numpy as np

from .equations import E, F
from .events import SwitchEvent, per_copy


class PatternSwitching:
    """``CPGNetwork``'s pattern switches (§7.11): arming them per trial, firing them, switching."""

    def _build_switches(self, circuit) -> None:
        """Each switch's trigger input, and each joint's angle input (where a switch reads the angle it holds)."""
        self._switch_input = [None if s.input is None else circuit.inputs.index(s.input) for s in circuit.switches]
        self._angle_input = [
            None if j.angle_input is None else circuit.inputs.index(j.angle_input) for j in circuit.joints
        ]

    def _reset_switches(self) -> None:
        """A trial's start: the circuit's ``armed`` switches pending, none fired, no command held."""
        self._previous_phi = None
        self._switched = np.zeros((self.batch, len(self.circuit.switches)), dtype=bool)
        # (copies, joint, angle) whose theta_0 is set at the end of the tick: continuous switches, start_from_pose
        self._hold_at_switch: list[tuple[np.ndarray, int, np.ndarray]] = []
        self._pending_switches = [i for i, s in enumerate(self.circuit.switches) if s.armed]
        self._switch_at: dict[int, float] = {}  # switch index -> this trial's time for its trigger `at`
        #: the pattern switches so far (§7.11), in order
        self.switch_events: list[SwitchEvent] = []

    def arm_switches(self, indices) -> None:
        """Arm only the circuit's switches ``indices`` (of ``circuit.switches``) for this trial (``reset`` arms those
        marked ``armed`` again): how a controller chooses one of its presets per trial, or none."""
        chosen = sorted({int(i) for i in indices})
        for i in chosen:
            if not 0 <= i < len(self.circuit.switches):
                raise ValueError(f"switch index {i}: expected one below {len(self.circuit.switches)}")
        self._pending_switches = [i for i in chosen if not self._switched[:, i].all()]

    def set_switch_time(self, at: float) -> None:
        """Fire this trial's armed time-triggered switches at ``at`` s instead of their ``at`` (``reset`` restores it):
        how a trial puts a switch where its push is (E4.4, E4.7)."""
        for n in self._pending_switches:
            if self.circuit.switches[n].at is not None:
                self._switch_at[n] = float(at)

    def _hold_commands(self) -> None:
        """A continuous switch's last part: theta_0 := angle - G (MN_E - MN_F) with this tick's MN, so that the command
        equals the angle measured at the switch."""
        mn = self._mn
        for mask, j, angle in self._hold_at_switch:
            drive = self._gain[mask, j] * (mn[mask, 2 * j + E] - mn[mask, 2 * j + F])
            self.theta0[mask, j] = angle - drive
        self._hold_at_switch.clear()

    def _switches(self, phi: np.ndarray, control_dt: float) -> None:
        """The circuit's pattern switches (§7.11) whose trigger fires this tick: time ``at``, input level ``above``, or
        input rate ``rate_above`` (the change since the last tick over ``control_dt``; none on the first tick)."""
        for n in list(self._pending_switches):
            s, i = self.circuit.switches[n], self._switch_input[n]
            if s.at is not None:
                at = self._switch_at.get(n, s.at)  # a trial may move a time trigger (set_switch_time)
                due = np.full(self.batch, at - 1e-9 <= self.time)
            elif s.rate_above is not None:
                if self._previous_phi is None:
                    continue
                due = (phi[:, i] - self._previous_phi[:, i]) / control_dt > s.rate_above
            else:
                due = phi[:, i] > s.above
            due &= ~self._switched[:, n]
            if due.any():
                self._switched[due, n] = True
                patterns = {name: (rg.sigma_s, rg.sigma_f) for name, rg in s.joints.items()}
                kicks = {name: s.joint_kicks.get(name, s.kick) for name in s.joints}
                rates = {}
                if s.kick_direction == "motion":
                    kicks, rates = self._kicks_by_motion(kicks, phi, control_dt)
                self.switch_pattern(
                    patterns,
                    kick=kicks,
                    duration=s.kick_duration,
                    sensors=phi,
                    where=due,
                    inhibit=s.inhibit,
                    continuous=s.theta0 == "continuous",
                    name=s.name,
                    extension_rates=rates,
                )
                if self._switched[:, n].all():
                    self._pending_switches.remove(n)
        self._previous_phi = phi.copy()

    def _kicks_by_motion(self, kicks: dict[str, float], phi: np.ndarray, control_dt: float) -> tuple[dict, dict]:
        """``kick_direction: motion`` (issue 23's reading of E4.4: each joint kicked in the direction it is moving; the
        switch's direction is the injected current's, L1437): each joint's kick keeps its magnitude, its sign pushes
        the joint further the way it moves. Its rate toward extension is sign(G) d angle / dt over the last
        tick (G > 0 where + rotation is extension; the angle_input's change over ``control_dt``); a kick of +I goes
        into RG-F (§5's convention), so a joint moving toward extension gets -|kick|, one moving toward flexion
        +|kick|, one not moving (or on the trial's first tick, no rate yet) its kick as given. Returns the kicks per
        batch copy and the rates."""
        out, rates = {}, {}
        for name, kick in kicks.items():
            j = self.circuit.joint_index(name)
            source = self._angle_input[j]
            if self._previous_phi is None:
                rate = np.zeros(self.batch)
            else:
                rate = np.sign(self._gain[:, j]) * (phi[:, source] - self._previous_phi[:, source]) / control_dt
            out[name] = np.where(rate > 0, -abs(kick), np.where(rate < 0, abs(kick), kick))
            rates[name] = rate
        return out, rates

    def switch_pattern(
        self,
        patterns: dict[str, tuple[float, float]],
        kick: float | dict[str, float] = 1.0,
        duration: float = 0.2,
        sensors=None,
        where=None,
        inhibit=(),
        continuous: bool = True,
        name: str | None = None,
        extension_rates: dict | None = None,
    ) -> None:
        """§7.11: set each named joint's (sigma_s, sigma_f), reset its V = q = 0 (the author's later method, digest
        §5), and inject +kick into RG-F / -kick into RG-E for ``duration`` s; ``kick`` is one number or one per joint
        (its sign the direction of that joint's switch, L1437; a joint's value may be an array over the batch copies).
        ``inhibit``: joint pairs whose couplings are silenced (L1311; all copies, so ``where`` must then select all or
        none). ``where``: boolean mask of the batch copies to switch (default all).

        A position-commanded joint's theta_0 (if it names ``angle_input`` and ``sensors`` are given): ``continuous``
        (the default) sets theta_0 := angle - G (MN_E - MN_F) at the end of this tick, so the command equals the
        measured angle (the joint goes on from where it is); ``continuous=False`` sets theta_0 := the measured angle,
        the rule of the author's 2017 scripts (digest §5, last bullet; not the thesis's), whose circuit has its
        reflexes off: here the command then jumps by the offset the joint's reflexes held. Recorded in
        ``switch_events`` (with ``name`` and the ``extension_rates`` a motion-directed kick used)."""
        mask = np.ones(self.batch, dtype=bool) if where is None else np.asarray(where, dtype=bool)
        kicks = kick if isinstance(kick, dict) else dict.fromkeys(patterns, kick)
        if inhibit and not mask.all():
            raise ValueError("inhibiting couplings in some batch copies only: the copies share one coupling matrix")
        for joint, pattern in patterns.items():
            self._switch_joint(joint, pattern, kicks.get(joint, 0.0), duration, sensors, mask, continuous)
        if inhibit:
            self.inhibit_couplings(inhibit)
        else:
            self._update_coefficients()

        def switched(value) -> float | np.ndarray:  # one number, or the switched copies' when they differ
            return per_copy(np.broadcast_to(np.asarray(value, dtype=float), (self.batch,))[mask])

        rates = extension_rates or {}
        self.switch_events.append(
            SwitchEvent(
                time=self.time,
                patterns={joint: (float(s), float(f)) for joint, (s, f) in patterns.items()},
                kicks={joint: switched(kicks.get(joint, 0.0)) for joint in patterns},
                inhibited=tuple(tuple(pair) for pair in inhibit),
                copies=mask.copy(),
                name=name,
                kick_direction="motion" if rates else "fixed",
                extension_rates={joint: switched(rate) for joint, rate in rates.items()},
            )
        )

    def _switch_joint(self, joint: str, pattern, kick, duration: float, sensors, mask: np.ndarray, continuous: bool):
        """One joint's part of ``switch_pattern`` in the copies ``mask``: its pattern, V = q = 0, its kick, its
        theta_0."""
        sigma_s, sigma_f = pattern
        j = self.circuit.joint_index(joint)
        cols = [2 * j + E, 2 * j + F]
        for array, value in ((self.sigma_s, sigma_s), (self.sigma_f, sigma_f)):
            array[np.ix_(mask, cols)] = value
        self.sigma_in[np.ix_(mask, cols)] = sigma_s
        self.sigma_out[np.ix_(mask, cols)] = sigma_s
        self.y[np.ix_(mask, [0, 1], cols)] = 0.0
        self._pulse_amplitude[mask, j] = np.broadcast_to(kick, (self.batch,))[mask]
        self._pulse_remaining[mask, j] = duration
        self._pulsing = True
        source = self._angle_input[j]
        if sensors is not None and source is not None and self.circuit.command == "position":
            phi = np.broadcast_to(sensors, (self.batch, len(self.circuit.inputs)))
            self.theta0[mask, j] = phi[mask, source]
            if continuous:
                self._hold_at_switch.append((mask.copy(), j, phi[mask, source].copy()))
