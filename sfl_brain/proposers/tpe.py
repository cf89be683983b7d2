"""TPE (Optuna's ``TPESampler``) through Optuna's ask/tell interface, with the gate as an optional safety layer.

Each axis of the unit cube is a ``FloatDistribution(0, 1)``; the study maximises the score (eta for a success, 0
for a failure: :meth:`.Outcome.score`), with Optuna's defaults (``n_startup_trials`` 10 random trials first,
univariate); the sampler's seed is the run's. Optuna's constrained form (failure told as a constraint with
``Trial.set_constraint``) is not offered: it puts an infeasible trial in TPE's worse group, where a failure scored 0
already is, and asked the very same points as this one in all five seeds of the planar study. The safe optimiser is
:mod:`.safe_bo`.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field

from .base import Optimiser, OptimiserParams, Outcome


class TPEParams(OptimiserParams):
    """Optuna's TPE sampler."""

    kind: Literal["tpe"]
    n_startup_trials: int = Field(10, ge=1, le=100_000, description="random trials before the model (Optuna's default)")
    multivariate: bool = Field(False, description="one joint model of all axes (Optuna's default: one per axis)")


class TPE(Optimiser):
    Params = TPEParams

    def __init__(self, params: TPEParams, dim: int, seed: int) -> None:
        super().__init__(params, dim, seed)
        import optuna

        optuna.logging.set_verbosity(optuna.logging.WARNING)
        sampler = optuna.samplers.TPESampler(
            n_startup_trials=params.n_startup_trials,
            multivariate=params.multivariate,
            seed=int(np.random.SeedSequence([seed, 3]).generate_state(1)[0]),
        )
        self.study = optuna.create_study(direction="maximize", sampler=sampler)
        self.distributions = {f"u{i}": optuna.distributions.FloatDistribution(0.0, 1.0) for i in range(dim)}
        self.pending = None

    def propose(self) -> np.ndarray:
        self.pending = self.study.ask(self.distributions)
        return np.array([self.pending.params[f"u{i}"] for i in range(self.dim)], dtype=float)

    def redraw(self) -> np.ndarray:
        from optuna.trial import TrialState

        self.study.tell(self.pending, state=TrialState.FAIL)
        return self.propose()

    def tell(self, v: np.ndarray, outcome: Outcome) -> None:
        trial, self.pending = self.pending, None
        self.study.tell(trial, self.score(outcome))
