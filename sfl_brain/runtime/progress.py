"""Progress of a run on the terminal: trials done / planned, success rate, vigilance."""

from __future__ import annotations

import functools
from pathlib import Path

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from ..events import Progress as RunProgress
from ..scenario.plan import Plan


class ProgressView:
    def __init__(self, plan: Plan, enabled: bool = True) -> None:
        self.plan = plan
        self.console = Console(stderr=True)
        self.enabled = enabled
        self.bar = Progress(
            TextColumn("[bold]{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn("{task.fields[status]}"),
            TimeElapsedColumn(),
            console=self.console,
            disable=not enabled,
            transient=False,
        )
        self.task = None
        self.warned = False

    def __enter__(self):
        self.bar.start()
        self.task = self.bar.add_task(f"{self.plan.scenario.name}: starting", total=None, status="")
        return self

    def __exit__(self, *exc):
        self.bar.stop()
        return False

    def ready(self, seconds: float) -> None:
        self.bar.update(
            self.task,
            description=f"{self.plan.scenario.name}: trials",
            status=f"modules ready in {seconds:.2f} s",
        )

    def update(self, p: RunProgress) -> None:
        rate = p.successes / p.trials if p.trials else 0.0
        status = f"success {rate:5.1%}"
        if p.s_vig is not None:
            status += f"  s_vig {p.s_vig:+.3f}"
        if p.decisions:
            status += f"  decisions {p.decisions}"
        warning = p.stall_warning()
        if warning:
            status += f"  [bold yellow]{warning}[/]"
        if warning and not self.warned and not self.enabled:
            self.console.print(f"[yellow]sfl: {warning}[/]")  # no bar to show it on: say it once
            self.warned = True
        self.bar.update(self.task, total=p.planned, completed=p.trials, status=status)

    def report(self, run_dir: Path, summary: dict) -> None:
        # whole lines: a stop reason is read and grepped, never wrapped at the terminal's width
        say = functools.partial(self.console.print, soft_wrap=True)
        colour = {"completed": "green", "failed": "red", "stalled": "yellow", "interrupted": "yellow"}.get(
            summary["status"], "red"
        )
        say(f"[bold {colour}]{summary['status']}[/] (exit code {summary.get('exit_code')}): {run_dir}")
        if summary.get("stop_reason"):
            say(f"  stop reason: {summary['stop_reason']}", markup=False, highlight=False)
        rate = summary.get("success_rate")
        planned = summary.get("planned_trials")
        say(
            f"  trials {summary['trials']}{f' of {planned}' if planned is not None else ''} "
            f"(successes {summary['successes']}, failures {summary['failures']}), "
            f"decisions {summary['decisions']} (no-go {summary['no_go']}), "
            f"success rate {'-' if rate is None else f'{rate:.1%}'}, "
            f"final vigilance {summary['final_vigilance'] if summary['final_vigilance'] is not None else '-'}, "
            f"wall {summary['wall_time_s']:.1f} s"
        )
        dropped = summary.get("dropped") or {}
        total = sum(n for counts in dropped.values() for n in counts.values())
        if total:
            say(f"  dropped {total} messages that were not the run's own (by process: logs/*.counters.json)")
        recording = run_dir / "recording.rrd"
        view = f"rerun {recording}" if recording.exists() else f"rerun {run_dir / 'rerun'}/*.rrd (not merged)"
        say(f"  inspect: sfl inspect {run_dir}    view: {view}")
        if summary.get("protocol") == "learn" and summary["status"] in ("failed", "interrupted"):
            say(f"  resume: sfl run --resume {run_dir}    (goes on from its last recorded trial)")
