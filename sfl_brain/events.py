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
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .protocols import Progress


# ---------------------------------------------------------------- the modules' lifecycle and faults
@dataclass(frozen=True)
class ModuleAlive:
    """A module process (or a joined worker) declared its liveliness token: it serves requests."""

    name: str


@dataclass(frozen=True)
class ModuleSilent:
    """A module's liveliness lease expired while its process runs: the supervisor kills it."""

    name: str


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

    def describe(self) -> str:
        """The run's stop reason when nothing replaces the module."""
        when = " before it was ready" if self.before_ready else ""
        return (
            f"module `{self.name}` ({self.reference}) died with exit code {self.exit_code}{when}; "
            f"its log ({self.log_path}):\n{self.log_tail}"
        )


@dataclass(frozen=True)
class Restarted:
    """A module process that died was started again by its restart policy (``restart``-th of ``max_restarts``)."""

    name: str
    exit_code: int
    restart: int
    max_restarts: int


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
