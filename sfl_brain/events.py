"""What happens during a run, as typed values, and the hub that hands them to whoever listens.

The supervisor publishes the modules' lifecycle and faults (:class:`ModuleAlive`,
:class:`ModuleDied`, :class:`Restarted`, ...); a protocol publishes what it decided and tried
(:class:`DecisionsMade`, :class:`TrialRecorded`, :class:`TrialInterrupted`, :class:`ProgressUpdated`).
The run subscribes what it does with them: the records, the Rerun log, the progress bar, the
terminal lines. An event is a frozen dataclass and is dispatched on its type, never on a string.
Nothing here imports Zenoh; handlers run in the publisher's thread, one after another.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any


# ---------------------------------------------------------------- the modules' lifecycle and faults
@dataclass(frozen=True)
class ModuleAlive:
    """A module process (or a joined worker) declared its liveliness token: it serves requests."""

    name: str


@dataclass(frozen=True)
class ModuleSilent:
    """A module process lost its link to the run (its liveliness token went away) while it still runs: the supervisor
    waits for it to come back, and judges it by its progress (:class:`ModuleHung`), not by the silence."""

    name: str


@dataclass(frozen=True)
class ModuleStopped:
    """A module process the run waits on is stopped (SIGSTOP, Ctrl-Z, a debugger, a suspended machine): the run waits
    for it to continue (``stopped`` False once it runs again)."""

    name: str
    stopped: bool = True


@dataclass(frozen=True)
class ModuleHung:
    """A module process had the CPU for ``seconds`` without progress while the run waited on it (``doing``), past its
    time (``limit`` s, the scenario key ``key``): it is hung (:mod:`sfl_brain.runtime.liveness`). A body worker or
    controller is killed and restarted by its policy; a brain module fails the run."""

    name: str
    seconds: float
    key: str
    limit: float
    doing: str

    def describe(self) -> str:
        return (
            f"module `{self.name}` is hung: for {self.seconds:.1f} s it could run (neither stopped nor waiting for a "
            f"core) and did not finish {self.doing} ({self.key} is {self.limit:g} s)"
        )


@dataclass(frozen=True)
class ModuleDied:
    """A module process exited while the run needed it."""

    name: str
    reference: str
    exit_code: int
    log_path: str
    #: the last lines of its log, indented
    log_tail: str
    before_ready: bool = False
    #: why it died when the supervisor ended it (``hung: ...``), else ''
    cause: str = ""

    def describe(self) -> str:
        """The run's stop reason when nothing replaces the module."""
        when = " before it was ready" if self.before_ready else ""
        why = f" ({self.cause}: killed)" if self.cause else ""
        return (
            f"module `{self.name}` ({self.reference}) died with exit code {self.exit_code}{when}{why}; "
            f"its log ({self.log_path}):\n{self.log_tail}"
        )


@dataclass(frozen=True)
class Restarted:
    """A module process that died (or was ended as hung: ``cause``) was started again by its restart policy
    (``restart``-th of ``max_restarts``)."""

    name: str
    exit_code: int
    restart: int
    max_restarts: int
    cause: str = ""


@dataclass(frozen=True)
class PlacementYielded:
    """``pin_cpus: auto``: other work came to keep a pair's core busy (``busy``: which, how much), so the run's
    processes were placed again (``placement``: the new placement's line)."""

    busy: str
    placement: str


@dataclass(frozen=True)
class WorkerJoined:
    """A body worker started elsewhere (``sfl worker``) joined the run."""

    name: str


@dataclass(frozen=True)
class WorkerLeft:
    """A joined body worker's liveliness token went away."""

    name: str


# ---------------------------------------------------------------- what the protocol did
@dataclass(frozen=True)
class TrialInterrupted:
    """Trial ``trial`` lost its worker or controller mid-way and is sent again (``attempt``: 1 for the first retry)."""

    trial: int
    reason: str
    attempt: int


@dataclass(frozen=True)
class DecisionsMade:
    """Go/no-go decision rows (``kind: decision``), in decision order."""

    rows: list[dict]


@dataclass(frozen=True)
class TrialRecorded:
    """One finished trial's row (``kind: trial``)."""

    row: dict


@dataclass
class Progress:
    """What the CLI shows while a run goes on."""

    planned: int
    trials: int = 0
    successes: int = 0
    decisions: int = 0
    s_vig: float | None = None
    last: dict = field(default_factory=dict)
    #: the learn protocol's stall limits (None for protocols that cannot stall)
    max_decisions: int | None = None
    stall_decisions: int | None = None
    #: no-go decisions since the last go
    consecutive_nogo: int = 0
    #: decisions per trial over the recent trials (learn protocol)
    recent_decisions_per_trial: float | None = None

    #: trials before the decisions per trial are extrapolated to the budget (before: only a long no-go run warns)
    MIN_TRIALS_TO_EXTRAPOLATE = 10

    def stall_warning(self) -> str | None:
        """Why the run is likely to stop before its budget at the current no-go ratio, or None."""
        if self.max_decisions is None:
            return None
        left = self.planned - self.trials
        if left <= 0:
            return None
        if self.stall_decisions and self.consecutive_nogo >= self.stall_decisions // 4:
            return (
                f"stall likely: {self.consecutive_nogo} no-go decisions in a row "
                f"(the run stops as stalled at {self.stall_decisions})"
            )
        per_trial = self.recent_decisions_per_trial
        if per_trial is None and self.trials == 0 and self.decisions >= self.max_decisions // 10:
            return f"stall likely: {self.decisions} decisions and no trial yet (cap {self.max_decisions})"
        if per_trial is not None and self.trials < self.MIN_TRIALS_TO_EXTRAPOLATE:
            per_trial = None  # one slow first trial (empty maps, a cautious vigilance) is not a rate
        if per_trial is not None:
            # a burst of no-go (a scheduled vigilance passing its cautious end) is not a stall: warn only when the
            # run's own average rate predicts the cap as well as the recent one
            per_trial = min(per_trial, self.decisions / self.trials)
        if per_trial is not None and self.decisions + left * per_trial > self.max_decisions:
            reachable = self.trials + int(max(0, self.max_decisions - self.decisions) / per_trial)
            return (
                f"stall likely: {per_trial:.0f} or more decisions per trial, lately and on average; the cap of "
                f"{self.max_decisions} decisions stops the run near trial {reachable} of {self.planned}"
            )
        return None


@dataclass(frozen=True)
class ProgressUpdated:
    """The protocol's progress changed (after a trial, or during a long run of no-go decisions)."""

    progress: Progress


Handler = Callable[[Any], None]


class Events:
    """Publish events to the handlers subscribed to their exact type."""

    def __init__(self) -> None:
        self._handlers: dict[type, list[Handler]] = {}

    def subscribe(self, kinds: type | tuple[type, ...], handler: Handler) -> None:
        """Call ``handler(event)`` for every event of type ``kinds`` (or of any type in the tuple)."""
        for kind in kinds if isinstance(kinds, tuple) else (kinds,):
            self._handlers.setdefault(kind, []).append(handler)

    def publish(self, event: object) -> None:
        """Hand ``event`` to its type's handlers in the order they subscribed; what they raise goes to the publisher."""
        for handler in self._handlers.get(type(event), ()):
            handler(event)
