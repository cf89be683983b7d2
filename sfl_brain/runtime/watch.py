"""The supervisor's look at the processes the run waits on: which of them had the CPU past their time without
progress (:mod:`.liveness`), and which are stopped.

Every :data:`WATCH_PERIOD` s :class:`HangWatch` samples each group of processes judged together
(:func:`watched_units`) that the run waits on now (a request in flight, or its start), and names the hung ones; the
:class:`~.supervisor.Supervisor` decides what becomes of them (killed and restarted, or the run failed).
"""

from __future__ import annotations

import time
from collections.abc import Iterator, Mapping

from ..events import Events, ModuleHung, ModuleStopped
from ..scenario.plan import Plan
from .inbox import Pending
from .liveness import NoProgressClock, ProgressBoard, cpu_sample
from .pairs import lockstep_pairs
from .processes import Child

#: s between two looks at the processes the run waits on (:mod:`.liveness`)
WATCH_PERIOD = 0.5

#: what the run waits on a group of processes for: s of CPU without progress it may take, that time's scenario key,
#: what it is doing, and the requests it works on
Waited = tuple[float, str, str, tuple[int, ...]]


def watched_units(plan: Plan) -> dict[str, tuple[str, ...]]:
    """The processes judged together (:mod:`.liveness`) by each process's name: a body worker and its
    controller process take turns, so neither makes progress while the other holds it; every other process alone."""
    pairs, others = lockstep_pairs(plan)
    units: dict[str, tuple[str, ...]] = {name: (name,) for name in others}
    for pair in pairs:
        unit = (pair.body, pair.controller) if pair.controller is not None else (pair.body,)
        for name in unit:
            units[name] = unit
    return units


class HangWatch:
    """A clock of CPU time without progress for each group of processes the run waits on, and the processes seen
    stopped (each told once, on :class:`~sfl_brain.events.ModuleStopped`)."""

    def __init__(self, plan: Plan, events: Events) -> None:
        self.plan = plan
        self.events = events
        self.units = watched_units(plan)
        self._clocks: dict[tuple[str, ...], NoProgressClock] = {}
        self._next_watch = 0.0
        self._stopped: set[str] = set()  # processes the run waits on that were seen stopped (told once)

    def hung(
        self, board: ProgressBoard | None, children: Mapping[str, Child], pending: Mapping[int, Pending]
    ) -> Iterator[tuple[str, ModuleHung]]:
        """Every :data:`WATCH_PERIOD` s: look at each group of processes the run waits on (:meth:`waited_on`) and
        name, one by one, those that had the CPU past their time without progress."""
        now = time.monotonic()
        if now < self._next_watch or board is None:
            return
        self._next_watch = now + WATCH_PERIOD
        waited = self.waited_on(children, pending)
        for unit in [u for u in self._clocks if u not in waited]:
            del self._clocks[unit]
        watched = {name for unit in waited for name in unit}
        self.settle(children, [name for name in self._stopped if name not in watched])
        for unit, (limit, key, doing, tickets) in waited.items():
            procs = [children[name].proc for name in unit]
            samples = [cpu_sample(proc.pid) if proc is not None else None for proc in procs]
            self._tell_stopped(unit, samples)
            marks = (tuple(board.read(name)[1] for name in unit), tickets)
            clock = self._clocks.setdefault(unit, NoProgressClock())
            had = clock.update(samples, marks)
            if had <= limit:
                continue
            used = clock.used()
            spinning = [name for name, cpu in zip(unit, used, strict=True) if cpu > 0.25 * had]
            clock.reset()
            for name in spinning or unit:
                yield name, ModuleHung(name, had, key, limit, doing)

    def settle(self, children: Mapping[str, Child], names: list[str] | None = None) -> None:
        """Tell which of the processes seen stopped (``names``: all of them) run again, though the run no longer
        waits on them: their request may have been answered, or the run ended, before the next look."""
        for name in list(self._stopped) if names is None else names:
            proc = children[name].proc if name in children else None
            self._tell_stopped((name,), [cpu_sample(proc.pid) if proc is not None else None])

    def _tell_stopped(self, unit: tuple[str, ...], samples: list) -> None:
        """Say once when a process the run waits on is stopped, and when it runs again; one that is gone (no sample)
        is forgotten, not said to run: its exit is told elsewhere."""
        for name, sample in zip(unit, samples, strict=True):
            if sample is None:
                self._stopped.discard(name)
                continue
            stopped = sample.state in "Tt"
            if stopped != (name in self._stopped):
                (self._stopped.add if stopped else self._stopped.discard)(name)
                self.events.publish(ModuleStopped(name, stopped))

    def waited_on(self, children: Mapping[str, Child], pending: Mapping[int, Pending]) -> dict[tuple[str, ...], Waited]:
        """The groups of processes (:func:`watched_units`) the run waits on now, each with its time (s of CPU without
        progress), that time's scenario key, what it is doing, and the requests it works on: those with a request in
        flight (a brain module: ``timeouts.request``; a body worker and its controller: ``timeouts.trial``), and each
        process that is starting (``timeouts.ready``)."""
        timeouts = self.plan.scenario.timeouts
        waited: dict[tuple[str, ...], Waited] = {}
        for ticket, request in pending.items():
            if request.done or request.target not in children:
                continue
            unit = self.units[request.target]
            key = "timeouts.trial" if request.target in self.plan.bodies else "timeouts.request"
            tickets = waited.get(unit, (0, "", "", ()))[3] + (ticket,)
            waited[unit] = (request.limit, key, f"answering `{request.message.TAG}`", tickets)
        for child in children.values():
            if child.starting:
                waited.setdefault((child.name,), (timeouts.ready, "timeouts.ready", "coming alive", ()))
        return waited
