"""What arrives on the supervisor's one queue, a request in flight, and how a request is sent.

Zenoh callbacks (:func:`send_request`'s and the liveliness subscriber's), the processes' exit watchers and the run's
signal handler only put these values on the :class:`~.supervisor.Supervisor`'s queue; the thread that waits handles
them, one at a time.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import zenoh

from ..messages import Message, MessageError, NonFiniteError, decode, encode
from ..protocols.service import Interrupted, Outcome, RunError
from . import bus
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


def send_request(
    session: zenoh.Session,
    seal: bus.Seal,
    drops: bus.Drops,
    put: Callable[[object], None],
    run_id: str,
    ticket: int,
    target: str,
    message: Message,
    wait: float,
) -> None:
    """Send request ``ticket`` (``message``, signed) to ``target``; what comes back is ``put`` on the queue: each
    signed reply as :class:`Replied` (a controller that hung also as :class:`HungController`), then
    :class:`QueryEnded` when Zenoh ends the query (after ``wait`` s at most). An unsigned reply is dropped."""
    key_expr = bus.key(run_id, target, message.TAG)
    nonce, payload = seal.seal_request(key_expr, encode(message))

    def on_reply(reply: zenoh.Reply) -> None:
        if reply.ok is not None:
            data = seal.open_reply(nonce, reply.ok.payload.to_bytes())
            if data is None:
                drops("unauthenticated", "reply", f"to `{message.TAG}` on {key_expr}")
                return
            try:
                put(Replied(ticket, decode(data)))
            except (MessageError, NonFiniteError) as exc:
                put(Replied(ticket, RunError(f"malformed reply from `{target}`: {exc}")))
        else:
            data = seal.open_reply(nonce, reply.err.payload.to_bytes())
            if data is None:  # Zenoh's own "Timeout" (QueryEnded decides), or a stranger's
                return
            text = data.decode(errors="replace")
            if text.partition(":")[0] == ControllerHung.__name__:
                put(HungController(target))
            put(Replied(ticket, remote_fault(target, message.TAG, text)))

    session.get(
        key_expr,
        zenoh.handlers.Callback(on_reply, lambda: put(QueryEnded(ticket)), indirect=False),
        payload=payload,
        timeout=wait,
        target=zenoh.QueryTarget.ALL,
        consolidation=zenoh.ConsolidationMode.NONE,  # every reply as it comes: a stranger's cannot hold ours
    )
