"""The conductor every protocol runs through, and the seed of each trial.

A protocol talks to modules only through messages (``Conductor.call`` for brain modules,
``Conductor.trials`` for bodies), over whatever hosts them (a
:class:`~sfl_brain.protocols.service.ModuleService`: every module in this process, or one process per module
over Zenoh; nothing here imports Zenoh or the supervisor). It publishes one row per decision and
per trial, and its progress, as :mod:`~sfl_brain.events`; the run writes the records, the Rerun
log and the progress bar from them.
"""

from __future__ import annotations

import time
from collections import Counter, deque
from collections.abc import Iterable, Iterator
from pathlib import Path

import numpy as np

from .. import messages as m
from ..events import DecisionsMade, Events, Progress, ProgressUpdated, TrialInterrupted, TrialRecorded
from ..recording.budget import TimeBudget
from ..recording.records import point_fields, trial_row
from ..scenario.plan import Plan
from .service import Interrupted, ModuleService, RunError

MAX_TRIAL_RETRIES = 3


def trial_seed(run_seed: int, trial_id: int) -> int:
    """Seed of one trial: the same whichever worker runs it."""
    return int(np.random.SeedSequence([run_seed, 7, trial_id]).generate_state(1)[0])


class Conductor:
    """The protocol's view of the running modules, and where it publishes what it does.

    ``replay``: the trial rows of an interrupted learn run (``sfl run --resume``), which ``run_learn`` replays
    before it goes on. While ``replaying``, nothing is published: the rows are in the records already.
    ``budget``: where the time in trials and records is counted (the protocol counts its decisions and learning).
    """

    def __init__(
        self,
        plan: Plan,
        modules: ModuleService,
        events: Events,
        run_dir: Path,
        replay: list[dict] | None = None,
        budget: TimeBudget | None = None,
    ) -> None:
        self.plan = plan
        self.modules = modules
        self.events = events
        self.run_dir = run_dir
        self.providers = plan.providers
        self.replay = list(replay or [])
        self.replaying = False
        self.budget = budget or TimeBudget()

    def call(self, message: m.Message) -> m.Message:
        return self.call_all(message)[0]

    def call_all(self, *messages: m.Message) -> list[m.Message]:
        """Send independent requests at once (to different modules) and wait for every reply."""
        timeout = self.plan.scenario.timeouts.request
        tickets = [self.modules.submit(self.providers[msg.TAG], msg, timeout) for msg in messages]
        outcomes: dict[int, object] = {}
        while len(outcomes) < len(tickets):
            outcomes.update(self.modules.wait_any([t for t in tickets if t not in outcomes]))
        replies = []
        for ticket in tickets:
            outcome = outcomes[ticket]
            if isinstance(outcome, Exception):  # a brain module's request is never retried
                raise RunError(str(outcome)) from None
            replies.append(outcome)
        return replies

    def trials(self, requests: Iterable[m.TrialRequest]) -> Iterator[tuple[m.TrialRequest, m.TrialResult, float]]:
        """Run trials on the body workers, each worker busy with one at a time.

        Yields (request, result, wall seconds) as trials complete. A trial :class:`Interrupted` by a
        body or controller crash is sent again (to any live worker), not counted as a failure, up to
        ``MAX_TRIAL_RETRIES`` times; any other fault ends the run.
        """
        todo = deque(requests)
        busy: dict[int, tuple[str, m.TrialRequest, float]] = {}
        retries: Counter = Counter()
        timeout = self.plan.scenario.timeouts.trial
        deadline_no_worker = None
        while todo or busy:
            in_use = {w for w, _, _ in busy.values()}
            idle = [w for w in self.modules.workers() if w not in in_use]
            while todo and idle:
                worker = idle.pop(0)
                request = todo.popleft()
                with self.budget.part("trials"):
                    ticket = self.modules.submit(worker, request, timeout)
                busy[ticket] = (worker, request, time.perf_counter())
            if not busy:
                if self.modules.coming():  # a body worker or controller restarting: waited for while it starts
                    deadline_no_worker = None
                else:
                    deadline_no_worker = deadline_no_worker or time.monotonic() + self.plan.scenario.timeouts.ready
                    if time.monotonic() > deadline_no_worker:
                        raise RunError("no body worker is alive to run trials")
                with self.budget.part("trials"):
                    self.modules.wait_for_workers(0.5)
                continue
            deadline_no_worker = None
            with self.budget.part("trials"):  # the waits only: a part must not stay open across the yield
                finished = list(self.modules.wait_any(list(busy)))
            for ticket, outcome in finished:
                worker, request, started = busy.pop(ticket)
                if isinstance(outcome, Interrupted):
                    retries[request.trial_id] += 1
                    if retries[request.trial_id] > MAX_TRIAL_RETRIES:
                        raise RunError(f"trial {request.trial_id} interrupted {MAX_TRIAL_RETRIES + 1} times: {outcome}")
                    self.events.publish(TrialInterrupted(request.trial_id, str(outcome), retries[request.trial_id]))
                    todo.appendleft(request)
                    continue
                if isinstance(outcome, Exception):
                    raise RunError(str(outcome))
                yield request, outcome, time.perf_counter() - started

    def _publish(self, *events) -> None:
        """Publish ``events``, unless the run is replaying recorded trials (they are in the records already)."""
        if not self.replaying:
            with self.budget.part("records"):
                for event in events:
                    self.events.publish(event)

    def record_decisions(self, rows: list[dict]) -> None:
        self._publish(DecisionsMade(rows))

    def record_trial(
        self,
        progress: Progress,
        trial: int,
        result: m.TrialResult,
        wall: float,
        point: dict | None = None,
        learning: dict | None = None,
    ) -> None:
        """Count a finished trial in ``progress`` and publish its row, then the progress."""
        progress.trials += 1
        progress.successes += int(result.success)
        row = trial_row(trial, result, wall, progress.successes / progress.trials, point, learning)
        progress.last = row
        self._publish(TrialRecorded(row), ProgressUpdated(progress))

    def report_progress(self, progress: Progress) -> None:
        self._publish(ProgressUpdated(progress))

    def trial_request(self, trial_id: int, unit: np.ndarray, log: bool) -> m.TrialRequest:
        physical = self.plan.to_physical(unit)
        return m.TrialRequest(
            trial_id=trial_id,
            seed=trial_seed(self.plan.scenario.seed, trial_id),
            body_params=physical["body"],
            controller_params=physical["controller"],
            log=log,
        )

    def should_log_body(self, trial_id: int) -> bool:
        every = self.plan.scenario.record.body_every
        return every > 0 and trial_id % every == 0

    def point(self, unit: np.ndarray) -> dict:
        """The record fields of a point of the parameter space (unit and physical coordinates)."""
        return point_fields(self.plan.scenario.space, unit)
