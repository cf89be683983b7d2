"""What arrives on the supervisor's one queue, and a request in flight.

Zenoh callbacks, the processes' exit watchers and the run's signal handler only put these values on the
:class:`~.supervisor.Supervisor`'s queue; the thread that waits handles them, one at a time.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..messages import Message
from ..protocols.service import Interrupted, Outcome, RunError
from .ticklink import ControllerHung, LinkError

#: exception types a module host names in an error reply that mean "cut short, send it again"
RETRYABLE = frozenset({LinkError.__name__, ControllerHung.__name__})


@dataclass(frozen=True)
class TokenDeclared:
    """A liveliness token with a valid proof: ``nonce`` is the spawn it was made for."""

    name: str
    nonce: str


@dataclass(frozen=True)
class TokenGone:
    name: str
    nonce: str


@dataclass(frozen=True)
class Replied:
    """A signed reply (or error reply) to request ``ticket``."""

    ticket: int
    outcome: Outcome


@dataclass(frozen=True)
class QueryEnded:
    """Zenoh finished request ``ticket`` (after its replies, or at its time-out without one)."""

    ticket: int


@dataclass(frozen=True)
class HungController:
    """Body worker ``body`` found its controller process hung (:class:`~sfl_brain.runtime.ticklink.ControllerHung`)."""

    body: str


@dataclass(frozen=True)
class Wake:
    """Nothing happened: wakes the waiting thread to look at :meth:`Supervisor.raise_at_wait`'s request."""


@dataclass
class Pending:
    target: str
    message: Message
    outcome: Outcome | None = None
    done: bool = False
    #: s its target may have the CPU without answering (``timeouts.request`` or ``timeouts.trial``)
    limit: float = float("inf")


def remote_fault(target: str, tag: str, text: str) -> RunError | Interrupted:
    """The fault of an error reply ``text`` (``ExceptionType: detail``, as the host sends it)."""
    fault = Interrupted if text.partition(":")[0] in RETRYABLE else RunError
    return fault(f"`{target}` failed on `{tag}`: {text}")
