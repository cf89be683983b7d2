"""An open-loop controller: sinusoidal motor voltages, no feedback (a baseline and a benchmark load)."""

from __future__ import annotations

import math

import numpy as np
from pydantic import Field

from sfl_brain.body import Controller
from sfl_brain.module import ModuleParams


class OpenLoopParams(ModuleParams):
    amplitude: float = Field(2.0, ge=0, description="V")
    frequency: float = Field(1.0, gt=0, description="Hz")
    control_dt: float = Field(0.01, gt=0)


class OpenLoopController(Controller):
    """Sinusoidal hip and knee voltages in anti-phase between the legs; ignores the sensors."""

    Params = OpenLoopParams
    READS = ()
    WRITES = ("v_hip_l", "v_hip_r", "v_knee_l", "v_knee_r")
    TRIAL_PARAMS = ("amplitude", "frequency")

    def configure(self, params: dict, seed: int) -> None:
        self.amplitude = float(params.get("amplitude", self.params.amplitude))
        self.frequency = float(params.get("frequency", self.params.frequency))
        self.t = 0.0

    def step(self, sensors: np.ndarray) -> np.ndarray:
        s = self.amplitude * math.sin(2 * math.pi * self.frequency * self.t)
        self.t += self.params.control_dt
        return np.array([s, -s, -abs(s), -abs(s)])
