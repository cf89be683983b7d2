"""Signals: what a body senses and what it takes as commands, as typed data.

A body declares each sensor and each command as a :class:`Signal` (name, unit, bounds, a one-line
meaning), as ROS 2's ``JointState`` or Gymnasium's ``spaces.Dict`` describe theirs. A controller
declares the names it reads and writes. The runtime matches them **by name**, once per run
(:func:`wiring`), so a body may list its signals in any order and carry more sensors than a
controller reads; ``sfl check`` reports a mismatch naming both ends before anything starts, and
``sfl list BODY`` prints the table.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from .registry import nearest

#: how far, as a share of its range, a sensor's value may stray outside its declared bounds (``Signal``): physics'
#: joint stops and contacts are soft (the conformance check allows this much; ``sfl_brain.gym`` widens its
#: observation space by it)
SENSOR_SLACK = 0.01


@dataclass(frozen=True)
class Signal:
    """One value a body senses or takes every control tick.

    ``low``, ``high``: for a sensor, the range its value stays in (the conformance check runs a short trial and
    fails a value outside it by more than 1% of the range: physics' joint stops and contacts are soft); for a
    command, the range the body acts on (beyond it, the body's own model decides: a motor saturates, a joint
    stops at its limit). The runtime does not clip or scale either: the bounds are a contract, checked, and shown
    by ``sfl list BODY``."""

    name: str
    unit: str
    low: float
    high: float
    meaning: str

    def __post_init__(self) -> None:
        if not self.name.isidentifier():
            raise ValueError(f"signal name {self.name!r} is not an identifier")
        if not (self.low <= self.high) or math.isnan(self.low) or math.isnan(self.high):
            raise ValueError(f"signal {self.name!r}: low {self.low} must not be above high {self.high}")


def names(signals: Iterable[Signal | str]) -> tuple[str, ...]:
    return tuple(s.name if isinstance(s, Signal) else s for s in signals)


class WiringError(ValueError):
    """A controller reads or writes a signal its body does not have (the text names both ends)."""


def wiring(
    provided: Sequence[Signal | str],
    wanted: Sequence[str],
    *,
    provider: str,
    consumer: str,
    what: str,
) -> np.ndarray | None:
    """Indices into ``provided`` of each name in ``wanted``, or None when they are the same list.

    ``what`` says which way the values flow, e.g. ``"reads sensors"``; a name the provider lacks
    raises :class:`WiringError` naming both ends, the missing names, the nearest provided name
    and the whole provided list.
    """
    have = names(provided)
    missing = [n for n in wanted if n not in have]
    if missing:
        spare = [n for n in have if n not in wanted]  # a name already matched is no hint
        hints = [f"{n} (did you mean `{nearest(n, spare)}`?)" if nearest(n, spare) else n for n in missing]
        raise WiringError(f"{consumer} {what} {', '.join(hints)} that {provider} does not have; it has {list(have)}")
    if tuple(wanted) == have:
        return None  # the same order: no reordering on the tick path
    return np.array([have.index(n) for n in wanted], dtype=np.intp)


def table(signals: Sequence[Signal], title: str) -> list[str]:
    """Lines of a fixed-width table of ``signals`` (for ``sfl list BODY``)."""
    rows = [(s.name, s.unit or "-", f"[{s.low:g}, {s.high:g}]", s.meaning) for s in signals]
    head = ("name", "unit", "range", "meaning")
    widths = [max(len(r[i]) for r in [head, *rows]) for i in range(3)]
    out = [title]
    for r in [head, *rows]:
        out.append("  " + "  ".join(f"{r[i]:<{widths[i]}}" for i in range(3)) + "  " + r[3])
    return out
