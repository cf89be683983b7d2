"""The proposer seam: what the learn protocol asks for the next parameter vector, and tells how it went.

A proposer works in the unit cube of the scenario's space (the plan maps it to physical values). The
learn protocol's loop is, for every proposer (``sfl_brain.protocols.run_learn``)::

    v = proposer.ask(gate)          # the next point to try, or None: the proposer stops the run
    result = trial(v)
    proposer.tell(v, outcome)       # success and eta of that trial

``gate`` is the run's go/no-go decision (the ACC's distances to the success and failure maps against
the vigilance threshold, Fig. 3.5 / 5.6): success-failure learning (:mod:`.sfl`) draws until the gate
says go; every other proposer asks the library it wraps and only has its point's decision recorded
as a go (:class:`Ungated`), so every run's records carry the same rows whichever proposer ran. The
brain modules learn from every trial whichever proposer chose it (the maps, rho and s_vig are
recorded alike); only success-failure learning uses them to choose.

A proposer is checkpointed by pickling it whole after each ``tell``: its library state and its random
generator, so a proposer restored from the checkpoint asks what the one that was stopped would have.
"""

from __future__ import annotations

import os
import pickle
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np
from pydantic import BaseModel, ConfigDict

from .. import messages as m


class ProposerParams(BaseModel):
    """Base of a proposer's parameters (``protocol.proposer`` in a scenario): the scenario's rules (frozen, unknown
    keys rejected, no coercion, finite numbers only); ``kind`` names the proposer."""

    model_config = ConfigDict(frozen=True, extra="forbid", strict=True, allow_inf_nan=False)


@dataclass(frozen=True)
class Outcome:
    """What a proposer is told of one trial: success, and eta when it succeeded (5.7-5.8, J^-1 scaled as the
    body reports it)."""

    success: bool
    eta: float | None

    def score(self) -> float:
        """The value a maximising optimiser sees: eta for a success, 0 for a failure (every success's eta is
        above 0, so a failure ranks below every success: the libraries rank, they do not read the value)."""
        return float(self.eta) if self.success and self.eta is not None else 0.0


class Gate(Protocol):
    """The run's go/no-go decision, as the protocol gives it to a proposer."""

    threshold: m.Threshold

    def evaluate(self, candidates: np.ndarray) -> m.Evaluation:
        """The ACC's go/no-go and distances of ``candidates`` (rows in the unit cube) at the current threshold."""

    def record(self, candidates: np.ndarray, evaluation: m.Evaluation, go_at: int | None, count: int) -> None:
        """Record the first ``count`` decisions of ``evaluation``; ``go_at`` is the one that said go, if any."""

    def rejected(self, consecutive: int) -> None:
        """Tell vigilance of a run of ``consecutive`` no-go decisions (it may move the threshold)."""


class Proposer:
    """Base of the proposers (module docstring). Subclasses set ``Params`` and implement ``ask`` and ``tell``."""

    #: decisions per trial are not capped for a proposer that does not gate (the progress view's stall warning)
    GATED = False

    def __init__(self, params, dim: int, seed: int) -> None:
        self.params = params
        self.dim = dim
        self.seed = seed
        #: why ``ask`` returned None
        self.stop_reason: str | None = None

    @classmethod
    def for_protocol(cls, protocol, dim: int, seed: int) -> Proposer:
        """The proposer of a learn ``protocol`` (its ``proposer`` block; a proposer that needs more of the protocol
        reads it here)."""
        return cls(protocol.proposer, dim, seed)

    def ask(self, gate: Gate) -> np.ndarray | None:
        raise NotImplementedError

    def tell(self, v: np.ndarray, outcome: Outcome) -> None:
        raise NotImplementedError

    def checkpoint(self, path: Path) -> None:
        """Pickle this proposer to ``path``, atomically (a reader never sees half a checkpoint)."""
        tmp = path.with_suffix(path.suffix + ".tmp")
        with open(tmp, "wb") as f:
            pickle.dump(self, f, protocol=pickle.HIGHEST_PROTOCOL)
        os.replace(tmp, path)

    @staticmethod
    def restore(path: Path) -> Proposer:
        """The proposer ``checkpoint`` wrote (a file of this run's own: pickle is not for files from elsewhere)."""
        with open(path, "rb") as f:
            return pickle.load(f)


class Ungated(Proposer):
    """A proposer that chooses without the gate: its point is tried whatever the maps say. The decision is
    still evaluated and recorded (a go), so the records show what the gate would have said of it."""

    def propose(self) -> np.ndarray:
        raise NotImplementedError

    def ask(self, gate: Gate) -> np.ndarray | None:
        v = np.clip(np.asarray(self.propose(), dtype=float), 0.0, 1.0)
        candidates = v[None, :]
        gate.record(candidates, gate.evaluate(candidates), go_at=0, count=1)
        return v
