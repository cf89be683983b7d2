"""TPE (Optuna's ``TPESampler``) through Optuna's ask/tell interface, without the gate; and its constrained
form, with failure as the constraint: the safe optimiser.

Each axis of the unit cube is a ``FloatDistribution(0, 1)``; the study maximises the score (eta for a
success, 0 for a failure: :meth:`.Outcome.score`). ``safe_tpe`` tells the sampler each trial's failure as a
constraint (``Trial.set_constraint``, Optuna >= 5: +1 violated for a fall, -1 satisfied for a success), so its model of
where good points lie is built from feasible trials only and it ranks infeasible ones below every feasible
one (Optuna's constrained TPE, after c-TPE, Watanabe & Hutter 2023). Both keep Optuna's defaults
(``n_startup_trials`` 10 random trials first, univariate); the sampler's seed is the run's.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field

from .base import Outcome, ProposerParams, Ungated


class TPEParams(ProposerParams):
    """Optuna's TPE sampler."""

    kind: Literal["tpe"]
    n_startup_trials: int = Field(10, ge=1, le=100_000, description="random trials before the model (Optuna's default)")
    multivariate: bool = Field(False, description="one joint model of all axes (Optuna's default: one per axis)")


class SafeTPEParams(TPEParams):
    """Optuna's TPE sampler with failure as a constraint."""

    kind: Literal["safe_tpe"]


class TPE(Ungated):
    Params = TPEParams

    def __init__(self, params: TPEParams, dim: int, seed: int) -> None:
        super().__init__(params, dim, seed)
        import optuna

        optuna.logging.set_verbosity(optuna.logging.WARNING)
        self.constrained = params.kind == "safe_tpe"
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

    def tell(self, v: np.ndarray, outcome: Outcome) -> None:
        trial, self.pending = self.pending, None
        if self.constrained:
            trial.set_constraint("failure", -1.0 if outcome.success else 1.0)
        self.study.tell(trial, outcome.score())


class SafeTPE(TPE):
    Params = SafeTPEParams
