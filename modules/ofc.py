"""OFC: qualitative adaptive reward, QARL (thesis §5.4.2, eqs. 5.1-5.3).

Successes are graded without a prior range: the first success earns rho_max; every
later one is placed linearly between the running worst and best qualities seen so
far (including itself) and mapped onto [rho_min, rho_max]. The ACC then learns the
success with that rho (5.1). With ``enabled: false`` every success learns with rho = 1.
"""

from __future__ import annotations

import math

from pydantic import Field, model_validator

from sfl_brain.messages import Grade, Reward
from sfl_brain.module import Module, ModuleParams, on


class OFCParams(ModuleParams):
    enabled: bool = Field(True, description="false: every success learns with rho = 1 (no QARL)")
    rho_min: float = Field(0.1, ge=0)
    rho_max: float = Field(2.5, gt=0)

    @model_validator(mode="after")
    def _ordered(self):
        if self.rho_min > self.rho_max:
            raise ValueError(f"rho_min ({self.rho_min}) must not exceed rho_max ({self.rho_max})")
        return self


class OFC(Module):
    """Qualitative adaptive reward rho for successful trials (eqs. 5.2-5.3)."""

    Params = OFCParams
    emits_telemetry = False  # nothing to show: its values go out in replies and the records

    def reset(self, seed: int) -> None:
        self.graded = 0
        self.eta_min = math.inf
        self.eta_max = -math.inf

    def reward(self, eta: float) -> float:
        """rho(k) of (5.2) for a success of quality eta; updates the running range (5.3)."""
        if not math.isfinite(eta):
            raise ValueError(f"trial quality must be finite, got {eta}")
        p = self.params
        first = self.graded == 0
        self.graded += 1
        self.eta_min = min(self.eta_min, eta)
        self.eta_max = max(self.eta_max, eta)
        if not p.enabled:
            return 1.0
        if first:
            return p.rho_max  # k = 0
        if self.eta_max == self.eta_min:
            return p.rho_max  # every success so far is equally the best
        return (p.rho_max - p.rho_min) / (self.eta_max - self.eta_min) * (eta - self.eta_min) + p.rho_min

    @on(Grade)
    def on_grade(self, msg: Grade) -> Reward:
        rho = self.reward(msg.eta)
        return Reward(rho=rho, eta_min=self.eta_min, eta_max=self.eta_max)
