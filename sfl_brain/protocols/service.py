"""The running modules as a protocol sees them: send a request, wait for replies, find a body worker.

A protocol (:mod:`sfl_brain.protocols`) needs nothing else from whatever hosts the modules, so the
same protocol code runs with every module in this process (:class:`sfl_brain.protocols.local.LocalModules`)
and with one process per module over Zenoh (:class:`sfl_brain.runtime.supervisor.Supervisor`). Nothing here
imports Zenoh.

A request ends in one of three ways, each a type: a reply (a :class:`~sfl_brain.messages.Message`),
:class:`Interrupted` (its target went away or lost its link mid-request: the request may be sent
again), or :class:`RunError` (the run cannot go on).
"""

from __future__ import annotations

from typing import Protocol

from ..messages import Message


class RunError(RuntimeError):
    """The run cannot go on (a module died, did not start, or failed a request)."""


class Interrupted(RuntimeError):
    """A request whose target died, left or lost its controller before answering (it may be sent again)."""


#: what a finished request gave: the reply, or the fault that ended it
Outcome = Message | RunError | Interrupted


class ModuleService(Protocol):
    """Requests to the run's modules by instance name, answered in any order."""

    def submit(self, target: str, message: Message, timeout: float) -> int:
        """Send ``message`` to instance ``target``; returns a ticket to wait on. ``timeout``: seconds."""
        ...

    def wait_any(self, tickets: list[int], timeout: float | None = None) -> list[tuple[int, Outcome]]:
        """Block until at least one of ``tickets`` is done (or ``timeout`` s pass: then ``[]``);
        return every done (ticket, outcome), each once."""
        ...

    def workers(self) -> list[str]:
        """Body workers that can run a trial now."""
        ...

    def wait_for_workers(self, timeout: float) -> None:
        """Block until the set of workers may have changed, at most ``timeout`` seconds."""
        ...

    def coming(self) -> bool:
        """A body worker (or its controller) is starting again: the run waits for it instead of giving up."""
        ...
