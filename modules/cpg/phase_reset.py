"""Phase resetting (thesis §4.4.4.1, L1268-1282; digest §7.10), as part of ``CPGNetwork`` (network.py).

"The rhythmic neurons were driven by ground contact force sensors" (L1270): when a sensory neuron (heel contact GB)
rises through 0.5, once per landing (``ResetTrigger``, events.py: a refractory time, none during the start-up
transient), either a pulse (default -1 into RG-F, +1 into RG-E, 40 ms) into a joint's RG, or (``mode: state``, §7.10's
alternative) a jump of a leg's RGs to a stored stance-onset state (V, q) measured on the unperturbed gait
(``calibrate.py``); switchable per trial (``set_phase_reset``).
"""

from __future__ import annotations

import numpy as np

from .equations import E, F
from .events import PhaseResetEvent, ResetTrigger


class PhaseResetting:
    """``CPGNetwork``'s phase resets (§7.10): how they act this trial, and firing them each tick."""

    def _build_phase_resets(self, circuit) -> None:
        """The circuit's ``phase_resets``: each entry's sensory neuron, joint, pulse, trigger, and stored state."""
        resets = circuit.phase_resets
        # (sensory neuron, joint, amplitude, duration) per entry, as four columns (none without entries)
        entries = [
            (self.sensor_names.index(r.sensor), circuit.joint_index(r.joint), r.amplitude, r.duration) for r in resets
        ]
        self._reset_arrays = tuple(np.array(column) for column in zip(*entries, strict=True))
        self._reset_trigger = ResetTrigger(
            [r.threshold for r in resets], [r.refractory for r in resets], [r.after for r in resets], self.batch
        )
        # a state reset's target per entry: the RG columns of its joints [E, F, E, F, ...] and their V and q
        # (None: the entry stores no complete state, so it can act as a pulse only)
        self._reset_states: list[tuple[np.ndarray, np.ndarray, np.ndarray] | None] = []
        for r in resets:
            if r.missing_states():
                self._reset_states.append(None)
                continue
            names = r.state_joints
            cols = np.array([2 * circuit.joint_index(name) + side for name in names for side in (E, F)])
            V = np.array([cell[0] for name in names for cell in (r.state[name].E, r.state[name].F)])
            q = np.array([cell[1] for name in names for cell in (r.state[name].E, r.state[name].F)])
            self._reset_states.append((cols, V, q))

    def _reset_phase_resets(self) -> None:
        """A trial's start: each entry acts as its file says, none has fired."""
        self.phase_reset_enabled = np.array([r.enabled for r in self.circuit.phase_resets], dtype=bool)
        self.phase_reset_as_state = np.array([r.mode == "state" for r in self.circuit.phase_resets], dtype=bool)
        self._reset_trigger.reset()
        #: the phase resets so far (§7.10), in order
        self.phase_reset_events: list[PhaseResetEvent] = []

    #: what ``set_phase_reset`` takes
    PHASE_RESET_MODES = ("off", "pulse", "state", "circuit")

    def set_phase_reset(self, mode: str) -> None:
        """How the circuit's phase resets act until the next ``reset`` (which restores "circuit"): "off" (none),
        "pulse" or "state" (every entry acts so, each still as its ``enabled``), "circuit" (each as its file says). A
        state reset needs every entry to store a state for each of its joints (ValueError naming those that do not)."""
        if mode not in self.PHASE_RESET_MODES:
            raise ValueError(f"phase_reset: expected one of {list(self.PHASE_RESET_MODES)}; got {mode!r}")
        resets = self.circuit.phase_resets
        problem = self.circuit.state_reset_problem() if mode == "state" else ""
        if problem:
            raise ValueError(f"phase_reset: {problem}")
        self.phase_reset_enabled = np.array([r.enabled and mode != "off" for r in resets], dtype=bool)
        as_state = [r.mode == "state" if mode == "circuit" else mode == "state" for r in resets]
        self.phase_reset_as_state = np.array(as_state, dtype=bool)

    def _phase_resets(self, rho: np.ndarray) -> None:
        """§7.10 (L1270-1282): a sensory neuron rising through its threshold (``ResetTrigger``: once per landing, not
        in the start-up transient) starts a pulse into its joint's RG, or sets its joints' RGs to the stance-onset
        state (V, q) the entry stores (``phase_reset_as_state``): a reset of the phase, wherever the rhythm was."""
        if not self._reset_arrays:
            return
        sensor, joint, amplitude, duration = self._reset_arrays
        fired = self._reset_trigger(rho[:, sensor], self.time, self.phase_reset_enabled)
        if fired is None:
            return
        for n in np.flatnonzero(fired.any(axis=0)):
            copies = fired[:, n]
            if self.phase_reset_as_state[n]:
                cols, V, q = self._reset_states[n]
                rows = np.flatnonzero(copies)[:, None]
                self.y[rows, 0, cols] = V
                self.y[rows, 1, cols] = q
            else:
                self._pulse_amplitude[copies, joint[n]] = amplitude[n]
                self._pulse_remaining[copies, joint[n]] = duration[n]
                self._pulsing = True
            mode = "state" if self.phase_reset_as_state[n] else "pulse"
            self.phase_reset_events.append(PhaseResetEvent(self.time, int(n), mode, copies.copy()))
