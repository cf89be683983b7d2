"""Vigilance: the risk threshold s_vig of the early-warning decision (thesis §3.3.4, §4.4.4, §5.6.3).

Three modes, one scenario key:

* ``fixed``: s_vig is a constant (chapter 3: 0.05, 0, -0.1, -0.2).
* ``scheduled``: s_vig is drawn inside the band y1 <= s_vig <= y2 of (4.14),
  y = a - b ln((x + c)^2), x the trial index: cautious at first, adventurous later.
* ``adaptive``: after each trial, N_s > N_f lowers s_vig by ``step`` (take risks),
  N_s < N_f raises it (avoid risks), clamped to [-D, +D], D the unit-space diameter.

In the scheduled and adaptive modes, after ``reject_limit`` consecutive no-go samples s_vig is
lowered one step and the search goes on (§5.6.3: "after 1000 samples have been rejected
sequentially ... the threshold of vigilance decreased a step"). A fixed threshold stays fixed.
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
from pydantic import Field

from sfl_brain.messages import Rejected, Threshold, TrialDone, VigilanceStart
from sfl_brain.module import Module, ModuleParams, on


class VigilanceParams(ModuleParams):
    mode: Literal["fixed", "scheduled", "adaptive"] = "fixed"
    value: float = Field(0.0, ge=-3.0, le=3.0, description="fixed s_vig, or the adaptive start")
    step: float = Field(0.01, gt=0, le=0.5, description="adaptive change per trial")
    reject_limit: int = Field(1000, ge=1, description="consecutive no-go samples before one step down")
    dim: int | None = Field(
        None,
        ge=1,
        le=8,
        description="parameter-space dimension for D = sqrt(dim) (default: the scenario's number of axes)",
    )
    a1: float = 0.9
    a2: float = 1.47
    b1: float = 0.15
    b2: float = 0.15
    c1: float = Field(20.0, gt=0)
    c2: float = Field(20.0, gt=0)


class Vigilance(Module):
    """Vigilance threshold s_vig: fixed, scheduled band (4.14) or adaptive (§5.6.3)."""

    Params = VigilanceParams
    emits_telemetry = False  # nothing to show: its values go out in replies and the records

    def reset(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)
        self.diameter = math.sqrt(self.params.dim or 2)
        self.s_vig = self._clamp(self.params.value)
        self.low = self.high = self.s_vig
        if self.params.mode == "scheduled":
            self._draw(0)

    def band(self, x: float) -> tuple[float, float]:
        """(y1, y2) of (4.14) at trial index x."""
        p = self.params
        y1 = p.a1 - p.b1 * math.log((x + p.c1) ** 2)
        y2 = p.a2 - p.b2 * math.log((x + p.c2) ** 2)
        return min(y1, y2), max(y1, y2)

    def _clamp(self, value: float) -> float:
        return float(min(self.diameter, max(-self.diameter, value)))

    def _draw(self, x: int) -> None:
        low, high = self.band(x)
        self.low, self.high = self._clamp(low), self._clamp(high)
        self.s_vig = float(self.rng.uniform(self.low, self.high))

    def _threshold(self) -> Threshold:
        return Threshold(s_vig=self.s_vig, low=self.low, high=self.high)

    @on(VigilanceStart)
    def on_start(self, msg: VigilanceStart) -> Threshold:
        return self._threshold()

    @on(TrialDone)
    def on_trial_done(self, msg: TrialDone) -> Threshold:
        mode = self.params.mode
        if mode == "scheduled":
            self._draw(msg.trial_index)
        elif mode == "adaptive":
            if msg.n_success > msg.n_failure:
                self.s_vig = self._clamp(self.s_vig - self.params.step)  # take risks
            elif msg.n_success < msg.n_failure:
                self.s_vig = self._clamp(self.s_vig + self.params.step)  # avoid risks
            self.low = self.high = self.s_vig
        return self._threshold()

    @on(Rejected)
    def on_rejected(self, msg: Rejected) -> Threshold:
        if self.params.mode != "fixed" and msg.consecutive % self.params.reject_limit == 0:
            self.s_vig = self._clamp(self.s_vig - self.params.step)
            self.low = min(self.low, self.s_vig)
        return self._threshold()
