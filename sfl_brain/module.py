"""The base contract every brain module, controller and body implements.

A module is plain Python: a frozen parameter schema (``Params``), ``reset(seed)``,
and handler methods marked with :func:`on`, each taking one message type and
returning the reply. Nothing here knows about Zenoh or processes; the runtime
(:mod:`sfl_brain.runtime.host`) hosts a module in a process and routes messages to it.

:meth:`Module.handle` refuses NaN and infinities in what a module receives and in the reply it
gives (:class:`~sfl_brain.messages.NonFiniteError`, naming the module, the message and the field),
so a non-finite value stops the run where it appears, in one process or over the bus.

A complete module::

    class Echo(Module):
        class Params(ModuleParams):
            gain: float = Field(1.0, ge=0)

        def reset(self, seed: int) -> None:
            self.rng = np.random.default_rng(seed)

        @on(Grade)
        def grade(self, msg: Grade) -> Reward:
            return Reward(rho=self.params.gain * msg.eta, eta_min=0.0, eta_max=1.0)
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, ClassVar

import numpy as np
from pydantic import BaseModel, ConfigDict

from .messages import Message, check_finite


class ModuleParams(BaseModel):
    """Base of parameter schemas: frozen, keyword-only, unknown keys rejected."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)


def on(message_type: type[Message]) -> Callable:
    """Mark a method as the handler of ``message_type``."""

    def mark(fn: Callable) -> Callable:
        fn._sfl_handles = message_type
        return fn

    return mark


class Module:
    """Base of all hosted modules. Subclasses declare ``Params`` and ``@on`` handlers."""

    Params: ClassVar[type[ModuleParams]] = ModuleParams
    #: one-line description shown by ``sfl list`` (defaults to the docstring's first line)
    summary: ClassVar[str] = ""
    #: message types this module handles, filled from the ``@on`` marks
    handles: ClassVar[dict[type[Message], str]] = {}
    #: message types this module sends to others and needs a producer for
    requires: ClassVar[tuple[type[Message], ...]] = ()
    #: False: this module has nothing to show (the OFC, vigilance): its host gives it no sink (``self.telemetry``
    #: stays None) and leaves Rerun unimported (about 0.8 s of CPU). True (the default): the recording opens at
    #: start-up, before the module is ready, so its cost never counts against a request's ``timeouts.request``
    emits_telemetry: ClassVar[bool] = True

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        found: dict[type[Message], str] = {}
        for klass in reversed(cls.__mro__):
            for name, attr in vars(klass).items():
                message_type = getattr(attr, "_sfl_handles", None)
                if message_type is not None:
                    found[message_type] = name
        cls.handles = found

    def __init__(self, params: ModuleParams | None = None, *, seed: int = 0) -> None:
        self.params = params if params is not None else self.Params()
        #: where this module's telemetry goes (a :class:`~sfl_brain.telemetry.TelemetrySink`): the
        #: runtime's Rerun sink when the run records, a test's capture, or None (nothing to show)
        self.telemetry = None
        #: the entity path prefix this module logs under (its instance name)
        self.entity = type(self).__name__.lower()
        self._deferred: list[Callable[[], None]] = []
        #: the handler of each message type, bound once (the control tick dispatches one per tick)
        self._handlers = {t: getattr(self, name) for t, name in self.handles.items()}
        self.reset(seed)

    def reset(self, seed: int) -> None:
        """Return to the initial state; everything random draws from ``seed``."""
        self.rng = np.random.default_rng(seed)

    def defer(self, work: Callable[[], None]) -> None:
        """Run ``work`` after the reply has left (e.g. logging), off the caller's critical path.

        The host runs deferred work right after it replies; anything still pending runs before
        the next message is handled, so deferred work never reorders with handlers.
        """
        self._deferred.append(work)

    def run_deferred(self) -> None:
        pending, self._deferred = self._deferred, []
        for work in pending:
            work()

    def handle(self, msg: Message, *, checked: bool = False) -> Message | None:
        """Dispatch a message to its handler by type.

        Raises :class:`~sfl_brain.messages.NonFiniteError` when ``msg`` or the reply holds NaN or
        an infinity. ``checked``: the caller has checked ``msg`` already (the codec decoded it, or a
        body built it from sensors it checked). A stream reply (a controller's command) is checked
        where it lands, by the body's decoder or its in-process link, so that a controller in another
        process still sends it and the body stops the trial at once instead of waiting for a command
        that never comes.
        """
        if self._deferred:
            self.run_deferred()
        handler = self._handlers.get(type(msg))
        if handler is None:
            raise TypeError(f"{type(self).__name__} does not handle {msg.TAG!r}")
        if not checked:
            check_finite(msg, self, "received")
        reply = handler(msg)
        if reply is not None and not reply.STREAM:
            check_finite(reply, self, "replied")
        return reply

    def close(self) -> None:
        """Release resources (physics spaces, files). Called once by the host at exit."""

    @classmethod
    def describe(cls) -> str:
        if cls.summary:
            return cls.summary
        doc = (cls.__doc__ or "").strip().splitlines()
        return doc[0] if doc else cls.__name__
