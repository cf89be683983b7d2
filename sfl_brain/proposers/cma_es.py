"""CMA-ES (Hansen's ``cma`` package) through its ask/tell interface, with the gate as an optional safety layer.

It minimises minus the score (eta for a success, 0 for a failure: :meth:`.Outcome.score`) in the unit cube
(``bounds: [0, 1]``, the package's default boundary handling), from the cube's centre with ``sigma0`` a
quarter of its width (the package's advice: the optimum within x0 +- 3 sigma0 of a domain of width 1) and the
package's default population (4 + 3 ln n). A population is asked at once and handed out one point per trial;
it is told when its last point has been tried. When the strategy stops (its own ``stop()`` criteria, e.g.
no change in f), it starts again from the centre with the next seed: the same settings, not IPOP's doubled
population (the package's ``fmin`` does no restart by default either). To keep it exploring (issue 33), it can also
start again when its step size falls below ``restart_below``, and from a novel point instead of the centre
(``restart_from: novel``: of ``novel_draws`` uniform draws, the one farthest from every success so far, among those
the gate says go to when the gate is on; those decisions are recorded, none starts a trial).

Behind the gate (``gate``, :meth:`.Optimiser.ask`): a vetoed point is one of the population, told as the worst
failure when the population is; a resampled point is replaced in the population by another draw of the same
distribution (``es.ask(1)``, as the package's own ``ask_and_eval`` resamples an infeasible point).
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field

from .base import Gate, Optimiser, OptimiserParams, Outcome


class CMAParams(OptimiserParams):
    """CMA-ES in the unit cube."""

    kind: Literal["cma"]
    sigma0: float = Field(0.25, gt=0.0, le=1.0, description="initial step size, in unit-cube widths")
    popsize: int | None = Field(
        None, ge=2, le=10_000, description="points per generation; None: the package's default 4 + 3 ln(dim)"
    )
    restart_below: float = Field(
        0.0,
        ge=0.0,
        le=1.0,
        description="start again when the step size (the largest standard deviation, unit-cube widths) falls below "
        "this; 0: only when the package's own stop() says so",
    )
    restart_from: Literal["centre", "novel"] = Field(
        "centre",
        description="where a restart starts: the cube's centre, or (novel) of `novel_draws` uniform draws the one "
        "farthest from every success so far, among those the gate says go to when the gate is on",
    )
    novel_draws: int = Field(64, ge=1, le=100_000, description="uniform draws a novel restart chooses from")


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
        self.successes: list[np.ndarray] = []  # every success's point (where a novel restart does not start)
        self.restart_rng = np.random.default_rng(np.random.SeedSequence([seed, 5]))

    def prepare(self, gate: Gate) -> None:
        """Start again before a new generation when the strategy stopped or its step size collapsed."""
        if self.asked < len(self.population):
            return
        collapsed = (
            self.params.restart_below > 0 and float(np.max(self.es.stds[: self.dim])) < self.params.restart_below
        )
        if collapsed or self.es.stop():
            self.restarts += 1
            self.es = self._start(self._restart_point(gate))

    def _restart_point(self, gate: Gate) -> list[float] | None:
        """Where a restart starts (``restart_from``): None for the centre."""
        if self.params.restart_from == "centre":
            return None
        draws = self.restart_rng.random((self.params.novel_draws, self.dim))
        if self.params.gate != "off":
            evaluation = gate.evaluate(draws)
            gate.record(draws, evaluation, tried=None, count=len(draws))
            if evaluation.go.any():
                draws = draws[np.asarray(evaluation.go, dtype=bool)]
        if not self.successes:
            return draws[0].tolist()
        known = np.asarray(self.successes)
        nearest = np.min(np.linalg.norm(draws[:, None, :] - known[None, :, :], axis=2), axis=1)
        return draws[int(np.argmax(nearest))].tolist()

    def _start(self, x0: list[float] | None = None):
        import cma

        seed = int(np.random.SeedSequence([self.seed, 2, self.restarts]).generate_state(1)[0] % (2**31 - 1)) + 1
        options = {"bounds": [0.0, 1.0], "seed": seed, "randn": StandardNormal(seed), "verbose": -9}
        if self.params.popsize is not None:
            options["popsize"] = self.params.popsize
        if self.dim == 1:  # the package needs two coordinates; the second is a dummy, never used
            options["bounds"] = [[0.0, 0.0], [1.0, 1.0]]
        x0 = (x0 or [0.5] * self.dim) + [0.5] * (max(2, self.dim) - self.dim)
        return cma.CMAEvolutionStrategy(x0, self.params.sigma0, options)

    def propose(self) -> np.ndarray:
        if self.asked == len(self.population):  # a new generation (prepare has started again if it was due)
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
        if outcome.success:
            self.successes.append(np.asarray(v, dtype=float))
        self.scores.append(-self.score(outcome))
        if len(self.scores) == len(self.population):
            self.es.tell(self.population, self.scores)
