"""Where a run's wall time went: ``time_budget`` in ``summary.json``, printed by ``sfl inspect``.

The run and its protocol open a :meth:`TimeBudget.part` around each stage (start-up, trials, decisions, learning,
records, shutdown). Parts nest: a part opened inside another (the decision rows written while the proposer asks)
counts for itself and not for the one around it, so no second is counted twice and the parts add up to the time
spent in them. What no part covers (the protocol's own bookkeeping between them) is the difference between
``wall_s`` and ``sum_s``.
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from contextlib import contextmanager

#: the parts of a run's wall time, in the order a run goes through them
PARTS = ("startup", "trials", "decisions", "learning", "records", "shutdown")

#: what each part holds (``sfl inspect`` and docs/records.md)
MEANING = {
    "startup": "sfl's launch and imports, the run folder, the module processes until ready",
    "trials": "waiting for the body workers' trials",
    "decisions": "the proposer's ask, with the ACC's go/no-go evaluations",
    "learning": "grading, the modules' learning, the proposer's tell and checkpoint",
    "records": "records.jsonl, the Rerun log, the progress line, the tables, the merge",
    "shutdown": "stopping the module processes",
}


class TimeBudget:
    """Wall seconds by part of a run (:data:`PARTS`), measured with ``time.perf_counter`` from its creation.

    ``launched``: seconds the process had run before (its interpreter, imports and the scenario's check, for ``sfl
    run``: :func:`process_age`), counted as start-up and in the wall time."""

    def __init__(self, launched: float | None = None) -> None:
        self.started = time.perf_counter() - (launched or 0.0)
        self.seconds = dict.fromkeys(PARTS, 0.0)
        self.seconds["startup"] = launched or 0.0
        self._open: list[float] = []  # for each part open now, the seconds of the parts opened inside it

    @contextmanager
    def part(self, name: str) -> Iterator[None]:
        """Count the time in the ``with`` block for part ``name``, less the parts opened inside it."""
        if name not in self.seconds:
            raise ValueError(f"'part' must be in {PARTS} (got {name!r})")
        started = time.perf_counter()
        self._open.append(0.0)
        try:
            yield
        finally:
            elapsed = time.perf_counter() - started
            inner = self._open.pop()
            self.seconds[name] += elapsed - inner
            if self._open:
                self._open[-1] += elapsed

    def summary(self) -> dict:
        """``{"<part>_s": ..., "sum_s": ..., "wall_s": ...}``: the wall time is the time since the budget started."""
        wall = time.perf_counter() - self.started
        parts = {f"{name}_s": self.seconds[name] for name in PARTS}
        return {**parts, "sum_s": sum(parts.values()), "wall_s": wall}


def process_age() -> float | None:
    """Seconds since this process was launched, to the kernel's clock tick (Linux: ``/proc``); None elsewhere."""
    try:
        with open("/proc/self/stat", "rb") as f:
            stat = f.read()
        with open("/proc/uptime", "rb") as f:
            uptime = float(f.read().split()[0])
        start_ticks = int(stat[stat.rindex(b")") + 2 :].split()[19])  # field 22, starttime: ticks after boot
    except (OSError, ValueError, IndexError):
        return None
    return max(0.0, uptime - start_ticks / os.sysconf("SC_CLK_TCK"))


def budget_lines(budget: dict) -> list[str]:
    """``sfl inspect``'s lines of a run's ``time_budget``: one per part with its seconds and share of the wall time,
    then what no part covers and the wall time."""
    wall = budget.get("wall_s") or 0.0
    share = (lambda s: f"{100 * s / wall:5.1f}%") if wall > 0 else (lambda s: "     ")
    lines = []
    for name in PARTS:
        seconds = budget.get(f"{name}_s")
        if isinstance(seconds, int | float):
            lines.append(f"{name:>10} {seconds:9.3f} s {share(seconds)}  {MEANING[name]}")
    rest = wall - (budget.get("sum_s") or 0.0)
    lines.append(f"{'other':>10} {rest:9.3f} s {share(rest)}  the protocol's bookkeeping between the parts")
    lines.append(f"{'wall':>10} {wall:9.3f} s")
    return lines
