"""Random search: uniform draws in the unit cube, tried without the gate (the baseline the thesis's
"trying parameters blindly" names). It takes no ``gate``: uniform draws redrawn until the gate says go are
success-failure learning (:mod:`.sfl`), from the same stream of draws."""

from __future__ import annotations

from typing import Literal

import numpy as np

from .base import Optimiser, Outcome, ProposerParams


class RandomParams(ProposerParams):
    """Uniform random search, no parameters."""

    kind: Literal["random"]


class RandomSearch(Optimiser):
    Params = RandomParams

    def __init__(self, params: RandomParams, dim: int, seed: int) -> None:
        super().__init__(params, dim, seed)
        self.rng = np.random.default_rng(np.random.SeedSequence([seed, 1]))

    def propose(self) -> np.ndarray:
        return self.rng.random(self.dim)

    def tell(self, v: np.ndarray, outcome: Outcome) -> None:
        """Random search learns nothing."""
