"""A safe Bayesian optimiser: expected improvement weighted by the modelled probability of success.

Constrained expected improvement (cEI; Gardner et al. 2014, "Bayesian optimization with inequality constraints",
ICML; Gelbart, Snoek & Adams 2014) with scikit-learn's Gaussian processes:

- the probability that a point succeeds, P(s | x): a Gaussian-process classifier on every trial's success or
  failure (Laplace approximation; Matérn 5/2 kernel);
- eta where it succeeds: a Gaussian-process regressor on the successes (Matérn 5/2 plus white noise, normalised
  targets), its kernel's hyperparameters fitted again every ``refit_every`` trials;
- the next point: of ``candidates`` uniform draws in the unit cube, the one that maximises EI(x) P(s | x), where EI
  is the expected improvement over the best eta so far; among draws whose P(s | x) is at least
  ``min_success_probability`` only (a SafeOpt-style safe set; none pass: the most probable success is tried).

The first ``n_startup_trials`` points are uniform draws, as Optuna's samplers start; until a success is seen the
next point is the one most likely to succeed. Why this and not Optuna's constrained TPE (which the issue named):
Optuna puts an infeasible trial in TPE's worse group, where a failure scored 0 already is; in the planar study the
constrained and the plain TPE asked the same points in all five seeds (docs/results/baselines.md). Optuna's
``GPSampler`` models constraints too, but needs PyTorch.

Behind the gate (``gate``, :meth:`.Optimiser.ask`): a vetoed point is told as a failure (the classifier learns the
gate's no-go region); a resampled point is replaced by the next of the same draws in the order the acquisition ranks
them (the safe draws by EI(x) P(s | x), then the others by P(s | x)), the models unchanged.
"""

from __future__ import annotations

import warnings
from typing import Literal

import numpy as np
from pydantic import Field

from .base import Optimiser, OptimiserParams, Outcome


class SafeBOParams(OptimiserParams):
    """Constrained expected improvement with a Gaussian-process model of success."""

    kind: Literal["safe_bo"]
    n_startup_trials: int = Field(10, ge=1, le=100_000, description="uniform draws before the models")
    candidates: int = Field(1024, ge=16, le=1_000_000, description="uniform draws the acquisition is maximised over")
    min_success_probability: float = Field(
        0.5, ge=0.0, le=1.0, description="only draws at least this likely to succeed are tried (0: plain cEI)"
    )
    length_scale: float = Field(
        0.2, gt=0.0, le=10.0, description="the success classifier's Matérn length scale, unit-cube widths"
    )
    refit_every: int = Field(10, ge=1, le=100_000, description="trials between fits of the eta model's kernel")


class SafeBO(Optimiser):
    Params = SafeBOParams

    def __init__(self, params: SafeBOParams, dim: int, seed: int) -> None:
        super().__init__(params, dim, seed)
        self.rng = np.random.default_rng(np.random.SeedSequence([seed, 4]))
        self.points: list[np.ndarray] = []
        self.successes: list[bool] = []
        self.etas: list[float] = []
        self.kernel = None  # the eta model's fitted kernel, kept between refits

    def propose(self) -> np.ndarray:
        draws = self.rng.random((self.params.candidates, self.dim))
        self.ranked = (draws, self._ranking(draws), 0)
        return draws[self.ranked[1][0]]

    def redraw(self) -> np.ndarray:
        draws, order, at = self.ranked
        if at + 1 == len(order):  # every draw redrawn: new draws
            return self.propose()
        self.ranked = (draws, order, at + 1)
        return draws[order[at + 1]]

    def _ranking(self, draws: np.ndarray) -> np.ndarray:
        """The draws' indices, the one to try first first: in order for the first ``n_startup_trials``; by P(s | x)
        until a success is seen; then the safe draws by EI(x) P(s | x) and the others by P(s | x) (none safe: all
        by P(s | x))."""
        if len(self.points) < self.params.n_startup_trials:
            return np.arange(len(draws))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # scikit-learn's convergence notes on small data
            # the classifier needs both outcomes: with successes only, every draw is as likely to succeed; with
            # failures only (a gated run's vetoes are told as failures), the draws least like a failure first
            if not any(self.successes):
                return np.argsort(self._failure_likeness(draws), kind="stable")
            p_success = self._p_success(draws) if not all(self.successes) else np.ones(len(draws))
            score = self._expected_improvement(draws) * p_success
        safe = p_success >= self.params.min_success_probability
        by_p = np.argsort(-p_success, kind="stable")
        if not safe.any():
            return by_p
        safe_first = np.flatnonzero(safe)[np.argsort(-score[safe], kind="stable")]
        return np.concatenate([safe_first, by_p[~safe[by_p]]])

    def _p_success(self, draws: np.ndarray) -> np.ndarray:
        from sklearn.gaussian_process import GaussianProcessClassifier

        model = GaussianProcessClassifier(kernel=self._success_kernel(), optimizer=None)
        model.fit(np.asarray(self.points), np.asarray(self.successes))
        return model.predict_proba(draws)[:, list(model.classes_).index(True)]

    def _success_kernel(self):
        """The success classifier's kernel: a fixed Matérn 5/2 of ``length_scale``, scaled."""
        from sklearn.gaussian_process.kernels import ConstantKernel, Matern

        return ConstantKernel(4.0, "fixed") * Matern(self.params.length_scale, "fixed", nu=2.5)

    def _failure_likeness(self, draws: np.ndarray) -> np.ndarray:
        """Each draw's largest kernel covariance with a failure (the classifier's kernel): with failures only, the
        classifier cannot be fitted (one class), and a Gaussian-process model of success falls the most near a
        failure, so this orders the draws as its P(s | x) would, most likely success first when sorted up."""
        return self._success_kernel()(draws, np.asarray(self.points)).max(axis=1)

    def _expected_improvement(self, draws: np.ndarray) -> np.ndarray:
        from sklearn.gaussian_process import GaussianProcessRegressor
        from sklearn.gaussian_process.kernels import ConstantKernel, Matern, WhiteKernel

        x = np.asarray(self.points)[np.asarray(self.successes)]
        y = np.asarray(self.etas)
        refit = self.kernel is None or len(y) % self.params.refit_every == 0
        kernel = ConstantKernel() * Matern(nu=2.5) + WhiteKernel() if self.kernel is None else self.kernel
        seed = int(self.rng.integers(2**31 - 1))
        model = GaussianProcessRegressor(
            kernel=kernel, normalize_y=True, optimizer="fmin_l_bfgs_b" if refit else None, random_state=seed
        )
        model.fit(x, y)
        self.kernel = model.kernel_
        mu, sd = model.predict(draws, return_std=True)
        sd = np.maximum(sd, 1e-12)
        z = (mu - y.max()) / sd
        from scipy.stats import norm  # here: scipy.stats costs 0.75 s to import, and every sfl run imports this file

        return (mu - y.max()) * norm.cdf(z) + sd * norm.pdf(z)

    def tell(self, v: np.ndarray, outcome: Outcome) -> None:
        self.points.append(np.asarray(v, dtype=float))
        self.successes.append(bool(outcome.success))
        if outcome.success:
            self.etas.append(self.score(outcome))
