"""Success-failure learning's proposer: random draws gated by the ACC and vigilance (Fig. 3.5 / 5.6).

Candidates are drawn uniformly in the unit cube, one stream, in order, and the gate decides go or no-go
for each against the current vigilance threshold; the first go is tried. A batch is only how many of
the next draws the ACC evaluates in one request: draws left over after a go are evaluated again
(against the maps after learning) in the next request, so the records do not depend on the batch.
The learning itself (ACC, OFC, vigilance) happens in the brain modules after every trial, whichever
proposer ran; this proposer is the one that uses it.
"""

from __future__ import annotations

from collections import deque
from typing import Literal

import numpy as np

from .base import Gate, Outcome, Proposer, ProposerParams

#: a no-go streak this long is told to vigilance (it may move the threshold) before deciding further
REJECTED_EVERY = 1000


class SFLParams(ProposerParams):
    """Success-failure learning (the default); its batch and stall limits are the protocol's ``batch``,
    ``max_decisions`` and ``stall_decisions``."""

    kind: Literal["sfl"] = "sfl"


class SuccessFailure(Proposer):
    Params = SFLParams
    GATED = True

    def __init__(
        self,
        params: SFLParams,
        dim: int,
        seed: int,
        *,
        planned: int,
        batch: int = 64,
        max_decisions: int = 2_000_000,
        stall_decisions: int = 100_000,
    ) -> None:
        super().__init__(params, dim, seed)
        self.planned = planned
        self.max_decisions = max_decisions
        self.stall_decisions = stall_decisions
        self.trials = 0  # trials told
        self.rng = np.random.default_rng(np.random.SeedSequence([seed, 1]))
        self.max_batch = batch
        self.batch = min(8, batch)
        self.pool = np.empty((0, dim))
        self.go_window: deque[int] = deque(maxlen=20)  # decisions per go, recent trials: sizes the next batch
        self.decision = 0  # decisions made
        self.last_go = -1  # index of the last go decision
        self.consecutive_nogo = 0

    @classmethod
    def for_protocol(cls, protocol, dim: int, seed: int) -> SuccessFailure:
        """The protocol's batch and stall limits are this proposer's."""
        return cls(
            protocol.proposer,
            dim,
            seed,
            planned=protocol.trials,
            batch=protocol.batch,
            max_decisions=protocol.max_decisions,
            stall_decisions=protocol.stall_decisions,
        )

    def ask(self, gate: Gate) -> np.ndarray | None:
        while (why := self.cannot_go_on()) is None:
            if len(self.pool) < self.batch:
                self.pool = np.concatenate([self.pool, self.rng.random((self.batch - len(self.pool), self.dim))])
            candidates = self.pool[: self.batch]
            evaluation = gate.evaluate(candidates)
            chosen = None
            rejected = None
            used = 0
            for i in range(self.batch):
                used = i + 1
                self.decision += 1
                if evaluation.go[i]:
                    chosen = i
                    self.consecutive_nogo = 0
                    break
                self.consecutive_nogo += 1
                if self.consecutive_nogo % REJECTED_EVERY == 0:
                    rejected = self.consecutive_nogo
                    break  # the threshold may change: evaluate the next draws against the new one
                if self.decision >= self.max_decisions or self.consecutive_nogo >= self.stall_decisions:
                    break
            self.pool = self.pool[used:]
            gate.record(candidates, evaluation, chosen, used)
            if chosen is None:  # no go in the whole batch: look further ahead next time
                self.batch = min(self.max_batch, 2 * self.batch)
            else:
                self.go_window.append(self.decision - 1 - self.last_go)
                self.last_go = self.decision - 1
                self.batch = min(self.max_batch, max(4, 2 * max(self.go_window)))
            if rejected is not None:
                gate.rejected(rejected)
            if chosen is not None:
                return candidates[chosen].copy()
        self.stop_reason = why
        return None

    def cannot_go_on(self) -> str | None:
        """Why the run stops before its next decision: the decision cap or a stall (the run ends ``stalled``)."""
        if self.decision >= self.max_decisions:
            return (
                f"decision cap reached: {self.decision} decisions (protocol.max_decisions) gave "
                f"{self.trials} of {self.planned} trials"
            )
        if self.consecutive_nogo >= self.stall_decisions:
            return (
                f"no progress: {self.consecutive_nogo} decisions in a row without a trial (protocol.stall_decisions) "
                f"after {self.trials} of {self.planned} trials"
            )
        return None

    def tell(self, v: np.ndarray, outcome: Outcome) -> None:
        """Counted only: the maps and vigilance learn in the brain modules, and the draws do not depend on the
        outcome."""
        self.trials += 1
