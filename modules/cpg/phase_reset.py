"""Phase resetting (thesis §4.4.4.1, L1270-1282; digest §7.10), as part of ``CPGNetwork`` (network.py).

"The rhythmic neurons were driven by ground contact force sensors" (L1270): when a sensory neuron (heel contact GB)
rises through its threshold, once per landing (``ResetTrigger``, events.py: a refractory time, none during the start-up
transient), either a pulse (default -1 into RG-F, +1 into RG-E, 40 ms) goes into a joint's RG, or (``mode: state``,
§7.10's alternative) a leg's RGs jump to a stored stance-onset state (V, q) measured on the unperturbed gait
(``calibrate.py``); switchable per trial (``set_phase_reset``).
"""

from __future__ import annotations

import numpy as np

from .events import PhaseResetEvent


class PhaseResetting:
    """``CPGNetwork``'s phase resets (§7.10): how they act this trial, and firing them each tick."""

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
        if not self._resets:
            return
        sensor, joint, amplitude, duration, _ = self._reset_arrays
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
