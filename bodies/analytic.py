"""A body whose trial outcome is a known function of its parameters.

For testing brain modules (and the framework) without physics: the viable region
is a disc in the unit square (or a ball in the unit cube), and the trial quality
eta is a Gaussian bump centred at ``peak`` inside it. Parameters arrive by name
(``x``, ``y``, ``z``); missing ones default to 0.5.

Fault injection for supervision tests: ``crash_at_trial`` makes the process exit
abruptly the first time that trial is requested (the marker file records it),
so the runtime's retry path is exercised on a real dying process.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import ClassVar

import numpy as np
from pydantic import Field

from sfl_brain.body import Body, BodyParams
from sfl_brain.messages import TrialRequest

AXES = ("x", "y", "z")


class AnalyticParams(BodyParams):
    centre: tuple[float, ...] = Field((0.5, 0.5), min_length=1, max_length=3)
    radius: float = Field(0.3, gt=0, le=2)
    peak: tuple[float, ...] = Field(
        (0.6, 0.6), min_length=1, max_length=3, description="where the quality eta is highest"
    )
    width: float = Field(0.15, gt=0, description="spread of the quality bump")
    crash_at_trial: int = Field(-1, description="fault injection: exit abruptly on this trial id once")
    crash_marker: str | None = Field(None, description="file that records the injected crash happened")


class AnalyticBody(Body):
    """Known viability disc and quality field: a test body for brain modules."""

    Params = AnalyticParams
    TRIAL_PARAMS = AXES

    def start_trial(self, request: TrialRequest) -> None:
        p = self.params
        self._maybe_crash(request.trial_id)
        dim = len(p.centre)
        point = np.array([float(request.body_params.get(a, 0.5)) for a in AXES[:dim]])
        self.distance_to_centre = float(np.linalg.norm(point - np.array(p.centre)))
        self.success = self.distance_to_centre <= p.radius
        bump = np.exp(-np.sum((point - np.array(p.peak[:dim])) ** 2) / (2 * p.width**2))
        self.quality = float(bump) if self.success else 0.0

    def _maybe_crash(self, trial_id: int) -> None:
        p = self.params
        if trial_id != p.crash_at_trial:
            return
        marker = Path(p.crash_marker) if p.crash_marker else None
        if marker is not None and marker.exists():
            return
        if marker is not None:
            marker.write_text("crashed\n")
        os._exit(3)

    @property
    def done(self) -> bool:
        return True

    METRICS: ClassVar[dict[str, str]] = {"distance_to_centre": "unit space"}

    def outcome(self) -> tuple[bool, float, dict]:
        return self.success, self.quality, {"distance_to_centre": self.distance_to_centre}

    @staticmethod
    def viable(points: np.ndarray, centre=(0.5, 0.5), radius: float = 0.3) -> np.ndarray:
        """Ground truth: which unit-space points lie in the viable disc."""
        return np.linalg.norm(points - np.asarray(centre), axis=-1) <= radius
