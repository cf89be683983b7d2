"""What ``sfl study`` shows on the terminal while its runs go on (:class:`StudyView`)."""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field

from ..status import RunStatus
from .study import Outcome, RunFinished, RunProgress, RunStarted, StudyEvent, StudyRun


def _duration(seconds: float) -> str:
    seconds = max(0, int(round(seconds)))
    if seconds < 120:
        return f"{seconds} s"
    if seconds < 7200:
        return f"{seconds // 60} min {seconds % 60:02d} s"
    return f"{seconds // 3600} h {seconds % 3600 // 60:02d} min"


@dataclass
class _Running:
    planned: int | None
    where: str
    since: float
    trials: int = 0
    successes: int = 0
    last_trial: float = field(default_factory=time.monotonic)
    first_seen: tuple[float, int] | None = None  # (when, trials) of its first progress
    task: object = None

    def eta(self, now: float) -> float | None:
        """s until this run's last planned trial, at its rate since its first progress (None: not known yet)."""
        if self.planned is None or self.first_seen is None:
            return None
        since, count = self.first_seen
        if self.trials <= count or now <= since:
            return None
        return max(0, self.planned - self.trials) * (now - since) / (self.trials - count)


class StudyView:
    """The whole study on the terminal: runs done / running / queued / failed / stalled, each running run's trials
    so far and the study's ETA (a rich view; ``quiet``: plain lines, and a status line every ``every`` s).

    Every update comes from the study's own loop (no refresh thread): :meth:`tick` redraws."""

    QUIET_AFTER = 60.0  # s without a new trial before a running run is said to be quiet

    def __init__(self, runs: list[StudyRun], kept: dict[str, Outcome], quiet: bool, every: float = 60.0) -> None:
        from rich.console import Console
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn

        self.runs = {r.name: r for r in runs}
        self.order = {r.name: i for i, r in enumerate(runs, 1)}
        self.kept = kept
        self.outcomes: dict[str, Outcome] = dict(kept)
        self.running: dict[str, _Running] = {}
        self.quiet, self.every = quiet, every
        self.console = Console(stderr=True, soft_wrap=True, highlight=False)
        self.started = time.monotonic()
        self.last_line = self.started
        self.trials_here = 0  # trials run by this invocation (the ETA's rate)
        self.bar = Progress(
            TextColumn("{task.description}"),
            BarColumn(bar_width=24),
            MofNCompleteColumn(),
            TextColumn("{task.fields[status]}"),
            console=self.console,
            auto_refresh=False,
            disable=quiet,
        )
        self.study_task = None

    def __enter__(self):
        self.bar.start()
        self.study_task = self.bar.add_task("study", total=self._planned_total(), status="")
        self.tick()
        return self

    def __exit__(self, *exc):
        self.tick()
        self.bar.stop()
        return False

    def say(self, text: str, style: str = "") -> None:
        """One whole line above the bars (or on its own when quiet)."""
        if self.quiet:
            print(text, file=sys.stderr, flush=True)
        else:
            self.bar.console.print(text, style=style or None, markup=False)

    def _planned_total(self) -> int | None:
        planned = [r.planned for r in self.runs.values()]
        return None if any(p is None for p in planned) else sum(planned)

    def _counts(self) -> dict[str, int]:
        statuses = [o.status for o in self.outcomes.values()]
        return {
            "done": len(self.outcomes),
            "running": len(self.running),
            "failed": statuses.count(RunStatus.FAILED),
            "stalled": statuses.count(RunStatus.STALLED),
            "interrupted": statuses.count(RunStatus.INTERRUPTED),
        }

    def trials_done(self) -> int:
        """Trials done or no longer to do: a run that ended (even early) counts its whole plan."""
        ended = sum(
            self.runs[n].planned if self.runs[n].planned is not None else o.trials for n, o in self.outcomes.items()
        )
        return ended + sum(r.trials for r in self.running.values())

    def eta(self) -> float | None:
        """s until every run is done, at this invocation's rate of trials so far (None: not known yet)."""
        total = self._planned_total()
        elapsed = time.monotonic() - self.started
        if total is None or self.trials_here == 0 or elapsed <= 0:
            return None
        return max(0.0, total - self.trials_done()) / (self.trials_here / elapsed)

    def status_text(self) -> str:
        c = self._counts()
        queued = len(self.runs) - c["done"] - c["running"]
        text = f"{c['done']}/{len(self.runs)} done"
        if self.kept:
            text += f" ({len(self.kept)} kept)"
        text += f", {c['running']} running, {queued} queued, {c['failed']} failed, {c['stalled']} stalled"
        if c["interrupted"]:
            text += f", {c['interrupted']} interrupted"
        eta = self.eta()
        return text + (f", ETA {_duration(eta)}" if eta is not None else "")

    def show(self, event: StudyEvent) -> None:
        now = time.monotonic()
        if isinstance(event, RunStarted):
            run = self.runs[event.name]
            state = self.running[event.name] = _Running(run.planned, event.where, now)
            if self.quiet:
                self.say(f"sfl: [{self.order[event.name]}/{len(self.runs)}] {event.name} started on {event.where}")
            else:
                state.task = self.bar.add_task(f"  {event.name}", total=run.planned, status=event.where)
        elif isinstance(event, RunProgress):
            state = self.running.get(event.name)
            if state is None:  # a Dask task whose start event came late
                state = self.running[event.name] = _Running(self.runs[event.name].planned, "a Dask worker", now)
                if not self.quiet:
                    state.task = self.bar.add_task(f"  {event.name}", total=state.planned, status="")
            self.trials_here += max(0, event.trials - state.trials)
            state.first_seen = state.first_seen or (now, event.trials)
            state.trials, state.successes, state.last_trial = event.trials, event.successes, now
        elif isinstance(event, RunFinished):
            state = self.running.pop(event.name, None)
            if state is not None:
                self.trials_here += max(0, event.outcome.trials - state.trials)
                if state.task is not None:
                    self.bar.remove_task(state.task)
            else:
                self.trials_here += event.outcome.trials
            self.outcomes[event.name] = event.outcome
            self.say(self.finished_line(event.name, event.outcome), style=_STYLE.get(event.outcome.status, "red"))
        self.tick()

    def finished_line(self, name: str, o: Outcome) -> str:
        wall = f", {_duration(o.wall_s)}" if o.wall_s is not None else ""
        line = f"sfl: [{self.order[name]}/{len(self.runs)}] {name} {o.status}: {o.trials} trials{wall}, on {o.where}"
        return line + (f" ({o.reason})" if o.status != RunStatus.COMPLETED and o.reason else "")

    def tick(self) -> None:
        now = time.monotonic()
        if self.quiet:
            if self.running and now - self.last_line >= self.every:
                self.last_line = now
                each = ", ".join(
                    f"{n} {r.trials}/{r.planned if r.planned is not None else '?'}" for n, r in self.running.items()
                )
                self.say(f"sfl: study: {self.status_text()}; running: {each}")
            return
        if self.study_task is None:
            return
        self.bar.update(self.study_task, completed=self.trials_done(), status=self.status_text())
        for state in self.running.values():
            rate = f"success {state.successes / state.trials:.0%}" if state.trials else "starting"
            eta = state.eta(now)
            status = f"{rate}, {_duration(now - state.since)}{f', ETA {_duration(eta)}' if eta is not None else ''}"
            status += f", on {state.where}"
            if now - state.last_trial > self.QUIET_AFTER:
                status += f", no new trial for {_duration(now - state.last_trial)}"
            self.bar.update(state.task, completed=state.trials, status=status)
        self.bar.refresh()


_STYLE = {"completed": "green", "stalled": "yellow", "interrupted": "yellow"}
