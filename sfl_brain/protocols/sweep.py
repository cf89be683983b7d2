"""The sweep: every point of a grid over the parameter space run on the body, no learning."""

from __future__ import annotations

import itertools

import numpy as np

from ..events import Progress
from ..scenario.plan import Plan
from .conductor import Conductor


def grid_points(plan: Plan) -> np.ndarray:
    """Unit coordinates of the sweep grid (``steps`` points per axis, ends included)."""
    axes = [np.linspace(0.0, 1.0, a.steps) for a in plan.scenario.space]
    return np.array(list(itertools.product(*axes)), dtype=float)


def run_sweep(c: Conductor) -> dict:
    """Evaluate every grid point on the body (no learning), fanned out over the workers."""
    points = grid_points(c.plan)
    progress = Progress(planned=len(points))
    requests = (c.trial_request(i, p, c.should_log_body(i)) for i, p in enumerate(points))
    for request, result, wall in c.trials(requests):
        c.record_trial(progress, request.trial_id, result, wall, c.point(points[request.trial_id]))
    return {"planned_trials": len(points), "stop_reason": f"every grid point run ({len(points)})"}
