"""Proposers: what chooses the next parameter vector of a learn run (``protocol.proposer``; see :mod:`.base`).

- ``sfl``: success-failure learning, random draws gated by the ACC and vigilance (the thesis; the default);
- ``random``: uniform random search, no gate;
- ``cma``: CMA-ES (the ``cma`` package);
- ``tpe``: TPE (Optuna);
- ``safe_bo``: constrained expected improvement, a safe Bayesian optimiser that models the probability of success
  (scikit-learn's Gaussian processes).

``cma``, ``tpe`` and ``safe_bo`` take ``gate: off | veto | resample``: the early warning as their safety layer
(:meth:`.base.Optimiser.ask`).

``cma``, Optuna and scikit-learn are imported only when their proposer is made (``pip install 'sfl-brain[baselines]'``).
"""

from __future__ import annotations

from .base import VETOED, Gate, Optimiser, OptimiserParams, Outcome, Proposer, ProposerParams
from .cma_es import CMAES, CMAParams
from .random_search import RandomParams, RandomSearch
from .safe_bo import SafeBO, SafeBOParams
from .sfl import SFLParams, SuccessFailure
from .tpe import TPE, TPEParams

#: kind -> proposer class (its ``Params`` is what ``protocol.proposer`` validates against)
PROPOSERS: dict[str, type[Proposer]] = {
    "sfl": SuccessFailure,
    "random": RandomSearch,
    "cma": CMAES,
    "tpe": TPE,
    "safe_bo": SafeBO,
}

#: the library each proposer needs, beyond sfl-brain's own dependencies
NEEDS = {"cma": "cma", "tpe": "optuna", "safe_bo": "sklearn"}

__all__ = [
    "CMAES",
    "NEEDS",
    "PROPOSERS",
    "TPE",
    "VETOED",
    "CMAParams",
    "Gate",
    "Optimiser",
    "OptimiserParams",
    "Outcome",
    "Proposer",
    "ProposerParams",
    "RandomParams",
    "RandomSearch",
    "SFLParams",
    "SafeBO",
    "SafeBOParams",
    "SuccessFailure",
    "TPEParams",
]
