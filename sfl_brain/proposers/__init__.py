"""Proposers: what chooses the next parameter vector of a learn run (``protocol.proposer``; see :mod:`.base`).

- ``sfl``: success-failure learning, random draws gated by the ACC and vigilance (the thesis; the default);
- ``random``: uniform random search, no gate;
- ``cma``: CMA-ES (the ``cma`` package);
- ``tpe``: TPE (Optuna);
- ``safe_tpe``: Optuna's constrained TPE with failure as the constraint (a safe optimiser that models where
  trials fail).

``cma`` and Optuna are imported only when their proposer is made (``pip install 'sfl-brain[baselines]'``).
"""

from __future__ import annotations

from .base import Gate, Outcome, Proposer, ProposerParams, Ungated
from .cma_es import CMAES, CMAParams
from .random_search import RandomParams, RandomSearch
from .sfl import SFLParams, SuccessFailure
from .tpe import TPE, SafeTPE, SafeTPEParams, TPEParams

#: kind -> proposer class (its ``Params`` is what ``protocol.proposer`` validates against)
PROPOSERS: dict[str, type[Proposer]] = {
    "sfl": SuccessFailure,
    "random": RandomSearch,
    "cma": CMAES,
    "tpe": TPE,
    "safe_tpe": SafeTPE,
}

#: the library each proposer needs, beyond sfl-brain's own dependencies
NEEDS = {"cma": "cma", "tpe": "optuna", "safe_tpe": "optuna"}

__all__ = [
    "CMAES",
    "NEEDS",
    "PROPOSERS",
    "TPE",
    "CMAParams",
    "Gate",
    "Outcome",
    "Proposer",
    "ProposerParams",
    "RandomParams",
    "RandomSearch",
    "SFLParams",
    "SafeTPE",
    "SafeTPEParams",
    "SuccessFailure",
    "TPEParams",
    "Ungated",
]
