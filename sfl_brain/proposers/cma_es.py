"""CMA-ES (Hansen's ``cma`` package) through its ask/tell interface, with the gate as an optional safety layer.

It minimises minus the score (eta for a success, 0 for a failure: :meth:`.Outcome.score`) in the unit cube
(``bounds: [0, 1]``, the package's default boundary handling), from the cube's centre with ``sigma0`` a
quarter of its width (the package's advice: the optimum within x0 +- 3 sigma0 of a domain of width 1) and the
package's default population (4 + 3 ln n). A population is asked at once and handed out one point per trial;
it is told when its last point has been tried. When the strategy stops (its own ``stop()`` criteria, e.g.
no change in f), it starts again from the centre with the next seed: the same settings, not IPOP's doubled
population (the package's ``fmin`` does no restart by default either).

Behind the gate (``gate``, :meth:`.Optimiser.ask`): a vetoed point is one of the population, told as the worst
failure when the population is; a resampled point is replaced in the population by another draw of the same
distribution (``es.ask(1)``, as the package's own ``ask_and_eval`` resamples an infeasible point).
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field

from .base import Optimiser, OptimiserParams, Outcome


class CMAParams(OptimiserParams):
    """CMA-ES in the unit cube."""

    kind: Literal["cma"]
    sigma0: float = Field(0.25, gt=0.0, le=1.0, description="initial step size, in unit-cube widths")
    popsize: int | None = Field(
        None, ge=2, le=10_000, description="points per generation; None: the package's default 4 + 3 ln(dim)"
    )


class StandardNormal:
    """The package's ``randn(lam, dim)`` from our own seeded generator (picklable: the checkpoint keeps it)."""

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)

    def __call__(self, *shape: int) -> np.ndarray:
        return self.rng.standard_normal(shape)


class CMAES(Optimiser):
    Params = CMAParams

    def __init__(self, params: CMAParams, dim: int, seed: int) -> None:
        super().__init__(params, dim, seed)
        self.restarts = 0
        self.es = self._start()
        self.population: list[np.ndarray] = []
        self.asked = 0  # points of the population handed out
        self.scores: list[float] = []

    def _start(self):
        import cma

        seed = int(np.random.SeedSequence([self.seed, 2, self.restarts]).generate_state(1)[0] % (2**31 - 1)) + 1
        options = {"bounds": [0.0, 1.0], "seed": seed, "randn": StandardNormal(seed), "verbose": -9}
        if self.params.popsize is not None:
            options["popsize"] = self.params.popsize
        if self.dim == 1:  # the package needs two coordinates; the second is a dummy, never used
            options["bounds"] = [[0.0, 0.0], [1.0, 1.0]]
        x0 = [0.5] * max(2, self.dim)
        return cma.CMAEvolutionStrategy(x0, self.params.sigma0, options)

    def propose(self) -> np.ndarray:
        if self.asked == len(self.population):
            if self.es.stop():
                self.restarts += 1
                self.es = self._start()
            self.population = [np.asarray(x, dtype=float) for x in self.es.ask()]
            self.asked = 0
            self.scores = []
        x = self.population[self.asked]
        self.asked += 1
        return x[: self.dim]

    def redraw(self) -> np.ndarray:
        x = np.asarray(self.es.ask(1)[0], dtype=float)
        self.population[self.asked - 1] = x
        return x[: self.dim]

    def tell(self, v: np.ndarray, outcome: Outcome) -> None:
        self.scores.append(-self.score(outcome))
        if len(self.scores) == len(self.population):
            self.es.tell(self.population, self.scores)
