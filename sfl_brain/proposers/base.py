"""The proposer seam: what the learn protocol asks for the next parameter vector, and tells how it went.

A proposer works in the unit cube of the scenario's space (the plan maps it to physical values). The
learn protocol's loop is, for every proposer (``sfl_brain.protocols.run_learn``)::

    v = proposer.ask(gate)          # the next point to try, or None: the proposer stops the run
    result = trial(v)
    proposer.tell(v, outcome)       # success and eta of that trial

``gate`` is the run's go/no-go decision (the ACC's distances to the success and failure maps against
the vigilance threshold, Fig. 3.5 / 5.6): success-failure learning (:mod:`.sfl`) draws until the gate
says go. The optimisers (:class:`Optimiser`: CMA-ES, TPE, the safe Bayesian optimiser, random search) ask
the library they wrap; with ``gate: off`` (the default) they try that point whatever the gate says, with
``gate: veto`` or ``gate: resample`` the gate is their safety layer (:meth:`Optimiser.ask`). Every point a
proposer puts to the gate has its real decision recorded (``go`` is d_f - d_s > s_vig, eq. 3.3, for every
proposer), so the records of an ungated run show what success-failure learning would have decided. The
brain modules learn from every trial whichever proposer chose it (the maps, rho and s_vig are recorded
alike).

A proposer is checkpointed by pickling it whole after each ``tell``: its library state and its random
generator, so a proposer restored from the checkpoint asks what the one that was stopped would have.
"""

from __future__ import annotations

import os
import pickle
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Literal, Protocol

import numpy as np
from pydantic import BaseModel, BeforeValidator, ConfigDict, Field

from .. import messages as m


class ProposerParams(BaseModel):
    """Base of a proposer's parameters (``protocol.proposer`` in a scenario): the scenario's rules (frozen, unknown
    keys rejected, no coercion, finite numbers only); ``kind`` names the proposer."""

    model_config = ConfigDict(frozen=True, extra="forbid", strict=True, allow_inf_nan=False)


#: how an optimiser scores a failure: ``flat`` 0 (below every success), ``graded`` by how far the trial got
FailureScore = Literal["flat", "graded"]


@dataclass(frozen=True)
class Outcome:
    """What a proposer is told of one trial: success, and eta when it succeeded (5.7-5.8, J^-1 scaled as the
    body reports it); for a failure, how far it got (``progress`` in [0, 1], the mean of the fraction of the
    trial's duration it stayed up and of the finish line it covered; None when the body does not say). A point
    the gate vetoed (``gate: veto``) is told as :data:`VETOED`: a failure that was never tried."""

    success: bool
    eta: float | None
    progress: float | None = None
    vetoed: bool = False

    def score(self, failure: FailureScore = "flat") -> float:
        """The value a maximising optimiser sees: eta for a success; for a failure 0 (``flat``: every success's eta
        is above 0, so a failure ranks below every success) or ``progress - 1`` in [-1, 0] (``graded``: a failure
        that got further ranks higher, still below every success); a vetoed point scores as the worst failure, 0
        (flat) or -1 (graded). CMA-ES and TPE rank the values, they do not read them."""
        if self.success and self.eta is not None:
            return float(self.eta)
        if failure == "flat":
            return 0.0
        return -1.0 if self.vetoed or self.progress is None else float(np.clip(self.progress, 0.0, 1.0)) - 1.0


#: a point the gate vetoed, as an optimiser is told it (``gate: veto``)
VETOED = Outcome(success=False, eta=None, progress=0.0, vetoed=True)


class Gate(Protocol):
    """The run's go/no-go decision, as the protocol gives it to a proposer."""

    threshold: m.Threshold

    def evaluate(self, candidates: np.ndarray) -> m.Evaluation:
        """The ACC's go/no-go and distances of ``candidates`` (rows in the unit cube) at the current threshold."""

    def record(self, candidates: np.ndarray, evaluation: m.Evaluation, tried: int | None, count: int) -> None:
        """Record the first ``count`` decisions of ``evaluation`` (each its real go/no-go); ``tried`` is the
        candidate that is tried (the trial it starts), if any."""

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


def _yaml_off(value):
    """YAML 1.1 reads a bare ``off`` as false: ``gate: off`` means the word."""
    return "off" if value is False else value


GateMode = Annotated[Literal["off", "veto", "resample"], BeforeValidator(_yaml_off)]


class OptimiserParams(ProposerParams):
    """What every optimiser takes besides its own settings: the gate as a safety layer, and how a failure scores."""

    gate: GateMode = Field(
        "off",
        description="the early warning as a safety layer: off (every point the optimiser asks is tried; the gate's "
        "decision is recorded), veto (a no-go point is told to the optimiser as a failure, without a trial, and it "
        "is asked again) or resample (a no-go point is drawn again from the optimiser, nothing told)",
    )
    max_vetoes: int = Field(
        100,
        ge=0,
        le=100_000,
        description="no-go decisions per trial before the gate gives way: the next point is tried whatever it says",
    )
    failure_score: FailureScore = Field(
        "flat", description="a failure's score: flat (0) or graded (by how far the trial got, -1 to 0)"
    )


class Optimiser(Proposer):
    """A proposer that asks an optimising library (``propose``) and tells it each trial's score (``tell``), with
    the early warning as an optional safety layer (``params.gate``, :meth:`ask`). Every point it puts to the gate
    has its real decision recorded, gated or not."""

    def prepare(self, gate: Gate) -> None:
        """Before each :meth:`propose`: a hook for an optimiser that consults the gate on its own (CMA-ES's novel
        restarts)."""

    def propose(self) -> np.ndarray:
        """The library's next point (pending until it is told or redrawn)."""
        raise NotImplementedError

    def redraw(self) -> np.ndarray:
        """Another point in place of the pending one, which the library is not told of (``gate: resample``)."""
        raise NotImplementedError

    def score(self, outcome: Outcome) -> float:
        """The value the library maximises (:meth:`Outcome.score` with this optimiser's ``failure_score``)."""
        return outcome.score(getattr(self.params, "failure_score", "flat"))

    def ask(self, gate: Gate) -> np.ndarray | None:
        """The optimiser's next point, through the gate.

        - ``gate: off``: the point is tried whatever the gate says (its decision is recorded);
        - ``gate: veto``: a no-go point is told to the optimiser as :data:`VETOED` (score 0, or -1 with ``graded``
          failures: the worst failure), without a trial, and the optimiser is asked again;
        - ``gate: resample``: a no-go point is replaced by another draw of the optimiser (:meth:`redraw`), and
          the optimiser is told nothing of it.

        After ``max_vetoes`` no-go decisions in one trial the gate gives way: the next point is tried whatever it
        says (recorded as a no-go that started a trial), so a gated run never stalls.
        """
        mode = getattr(self.params, "gate", "off")
        self.prepare(gate)
        v = self._in_cube(self.propose())
        vetoes = 0
        while True:
            candidates = v[None, :]
            evaluation = gate.evaluate(candidates)
            if mode == "off" or evaluation.go[0] or vetoes >= self.params.max_vetoes:
                gate.record(candidates, evaluation, tried=0, count=1)
                return v
            gate.record(candidates, evaluation, tried=None, count=1)
            vetoes += 1
            if mode == "veto":
                self.tell(v, VETOED)
                self.prepare(gate)
                v = self._in_cube(self.propose())
            else:
                v = self._in_cube(self.redraw())

    @staticmethod
    def _in_cube(v) -> np.ndarray:
        return np.clip(np.asarray(v, dtype=float), 0.0, 1.0)
