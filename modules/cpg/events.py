"""What the network records while it runs, and when its phase resets fire: ``SwitchEvent`` (§7.11),
``PhaseResetEvent`` and ``ResetTrigger`` (§7.10), shared by network.py and calibrate.py."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class SwitchEvent:
    """A pattern switch that happened (§7.11): at ``time`` (s of CPG time, the start of the tick), the named joints
    took ``patterns`` (sigma_s, sigma_f) with the kicks ``kicks`` (into RG-F: their signs are the directions used; per
    switched copy, an array, when batch copies kicked differently), and the couplings between the joint pairs
    ``inhibited`` were silenced; ``copies``: which batch copies switched. ``name``: the circuit switch's label (a
    controller preset's name). ``kick_direction``: "fixed" or "motion"; with "motion", ``extension_rates`` holds each
    joint's sign(gain) d angle / dt at the switch (rad/s, > 0: moving toward extension, so its kick was -|kick|)."""

    time: float
    patterns: dict[str, tuple[float, float]]
    kicks: dict[str, float | np.ndarray]
    inhibited: tuple[tuple[str, str], ...]
    copies: np.ndarray
    name: str | None = None
    kick_direction: str = "fixed"
    extension_rates: dict[str, float | np.ndarray] = field(default_factory=dict)


@dataclass(frozen=True)
class PhaseResetEvent:
    """A phase reset that happened (§7.10): at ``time`` (s, the start of the tick), the circuit's ``phase_resets``
    entry ``entry`` acted as ``mode`` ("pulse" or "state") in the batch copies ``copies``."""

    time: float
    entry: int
    mode: str
    copies: np.ndarray


def per_copy(values) -> float | np.ndarray:
    """One number when every copy has the same, else the array: how an event records a value per batch copy."""
    values = np.asarray(values, dtype=float)
    return float(values.flat[0]) if np.all(values == values.flat[0]) else values.copy()


class ResetTrigger:
    """When phase resets fire (§7.10), one column per ``phase_resets`` entry: its sensory neuron rising through
    ``threshold`` (below it last tick, at or above it now), once per landing: not within ``refractory`` s of that
    entry's last firing (a heel bouncing), not before ``after`` s of trial time (the start-up transient). The network
    and ``calibrate.py`` (which records the gait's state at these instants) share it: the same rule for both."""

    def __init__(self, threshold, refractory, after, batch: int) -> None:
        self.threshold = np.asarray(threshold, dtype=float)
        self.refractory = np.asarray(refractory, dtype=float)
        self.after = np.asarray(after, dtype=float)
        self.batch = batch
        self._gated = bool(np.any(self.refractory > 0) or np.any(self.after > 0))  # else a bare rising edge
        self.reset()

    def reset(self) -> None:
        self._previous: np.ndarray | None = None  # which sensors were at or above threshold last tick
        self._last = np.full((self.batch, len(self.threshold)), -np.inf)  # s: each entry's last firing

    def __call__(self, rho: np.ndarray, time: float, enabled=True) -> np.ndarray | None:
        """``rho``: (batch, entries), the sensory neurons of this tick; ``time``: s, the tick's start. Which entries
        fire, (batch, entries) booleans, or None when none does (the common case, kept cheap)."""
        above = rho >= self.threshold
        previous, self._previous = self._previous, above
        if previous is None:
            return None
        rising = above & ~previous & enabled
        if not rising.any():
            return None
        if self._gated:
            rising &= (time >= self.after - 1e-9) & (time - self._last >= self.refractory - 1e-9)
            if not rising.any():
                return None
            self._last[rising] = time
        return rising
