"""CPU placement: a body worker and its controller process share one core; brain modules run elsewhere.

A lockstep pair takes turns and never runs at once: the body steps its physics while the
controller waits for the next frame, then the controller computes while the body waits for its
command. So the pair loses nothing by sharing a core, and it gains the cost of every hand-over:
on a 2-core VM an idle core halts, and waking a thread on the other core costs about 40 us, paid
two or more times per tick (frame in, command back), where a switch between two processes on one
core costs about 3 us. Measured side by side (``benchmarks/bus.py``, ticks of 90 us of work, two
processes blocking on a pipe): 1.9-2.1x the one-process time on two cores, 1.03-1.04x on one core;
the framework over Zenoh 1.7-2.3x on one core against 2.9-3.5x placed as before (not pinned, the
body polling), ``docs/results/benchmarks.md``. Both ends block on a shared core; neither polls (a
poll would starve the other).

:func:`place` decides, from the run's lockstep pairs, its other module processes, the cores
``sfl run`` may use (``taskset`` and container limits respected) and ``lockstep.pin_cpus``:

* ``auto`` (the default): when the run may use more than one core, each body worker and its
  controller process share a core of their own, the first pair the last usable core, the next
  pair the core before it; the brain modules are pinned to the cores no pair has, when there are
  any (they work between trials, while the pairs wait). With more pairs than cores nothing is
  pinned: the scheduler spreads them better than a fixed share would.
* ``always``: the same, and with more pairs than cores the pairs share the cores in turn.
* ``never``: nothing is pinned (two runs side by side without ``taskset``, whose pairs would
  otherwise pick the same core; a machine where something else is pinned to the last cores).

On one core, where the OS offers no CPU affinity (macOS, Windows), or when every controller runs
inside its body worker (``colocate: true``: no pair to place), nothing is pinned. The supervisor
itself is never pinned. ``taskset -c 0-2 sfl run ...`` and ``taskset -c 3-5 sfl run ...`` keep two
runs on cores of their own.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from dataclasses import dataclass, field

#: lockstep.pin_cpus values
MODES = ("never", "auto", "always")


@dataclass(frozen=True)
class Pair:
    """A body worker and the controller process it exchanges ticks with (None: colocated in it)."""

    body: str
    controller: str | None


@dataclass(frozen=True)
class Placement:
    """Where each module process of a run is pinned (``cores``; a process not named is not pinned)
    and why (``reason``: one sentence, the run's log line)."""

    mode: str
    usable: tuple[int, ...]
    cores: dict[str, tuple[int, ...]] = field(default_factory=dict)
    reason: str = ""

    def of(self, instance: str) -> list[int] | None:
        """The cores of ``instance`` as a host spec takes them (None: not pinned)."""
        cores = self.cores.get(instance)
        return list(cores) if cores else None

    def describe(self) -> str:
        """The line a user sees: what shares which core, or why nothing is pinned."""
        where = f"lockstep.pin_cpus: {self.mode}, usable cores {cpu_list(self.usable)}"
        return f"lockstep placement ({where}): {self.reason}"

    def to_json(self) -> dict:
        return {
            "mode": self.mode,
            "usable_cores": list(self.usable),
            "cores": {name: list(cores) for name, cores in self.cores.items()},
            "reason": self.reason,
        }


def cpu_list(cpus: Iterable[int]) -> str:
    """``0-3,6``, as ``taskset -c`` writes a list of cores; ``none`` when empty."""
    cpus = sorted(set(cpus))
    if not cpus:
        return "none"
    runs = []
    start = prev = cpus[0]
    for cpu in cpus[1:]:
        if cpu != prev + 1:
            runs.append((start, prev))
            start = cpu
        prev = cpu
    runs.append((start, prev))
    return ",".join(str(a) if a == b else f"{a}-{b}" for a, b in runs)


def place(pairs: list[Pair], others: list[str], cpus: list[int], mode: str) -> Placement:
    """Where each lockstep pair and the other module processes (``others``: brain modules, colocated
    body workers) run, on the usable ``cpus``, under ``lockstep.pin_cpus`` ``mode``. Pure: the same
    arguments give the same placement."""
    if mode not in MODES:
        raise ValueError(f"lockstep.pin_cpus must be one of {MODES} (got {mode!r})")
    usable = tuple(sorted(cpus))
    paired = [p for p in pairs if p.controller is not None]

    def unpinned(why: str) -> Placement:
        return Placement(mode, usable, {}, f"nothing pinned: {why}")

    if mode == "never":
        return unpinned("lockstep.pin_cpus is never")
    if not usable:
        return unpinned("this OS offers no CPU affinity")
    if len(usable) == 1:
        return unpinned("one usable core")
    if not paired:
        return unpinned("no body worker has a controller process of its own (colocated, or none)")
    if len(paired) > len(usable) and mode == "auto":
        return unpinned(
            f"{len(paired)} body-controller pairs on {len(usable)} cores are left to the scheduler "
            "(lockstep.pin_cpus: always shares the cores in turn)"
        )
    from_last = usable[::-1]
    cores: dict[str, tuple[int, ...]] = {}
    said = []
    for i, pair in enumerate(paired):
        core = from_last[i % len(from_last)]
        cores[pair.body] = cores[pair.controller] = (core,)
        said.append(f"{pair.body} and {pair.controller} share core {core}")
    rest = tuple(c for c in usable if c not in {core for (core,) in cores.values()})
    if others and rest:
        for name in others:
            cores[name] = rest
        said.append(f"{', '.join(others)} on {'core' if len(rest) == 1 else 'cores'} {cpu_list(rest)}")
    elif others:
        said.append(f"{', '.join(others)} not pinned (no core left)")
    return Placement(mode, usable, cores, "; ".join(said))


def usable_cpus() -> list[int]:
    """The cores this process may run on (respects ``taskset`` and container limits); empty
    where the OS offers no CPU affinity (macOS, Windows), so that nothing is ever pinned there."""
    if hasattr(os, "sched_getaffinity"):
        return sorted(os.sched_getaffinity(0))
    return []


def pin(cpus: Iterable[int] | None) -> None:
    """Pin every thread of this process to ``cpus`` (None: leave it as it is). Threads started
    later inherit it from the thread that starts them."""
    if cpus is None or not hasattr(os, "sched_setaffinity"):
        return
    target = set(cpus)
    try:
        threads = [int(t) for t in os.listdir("/proc/self/task")]
    except OSError:
        threads = [0]
    for tid in threads:
        try:
            os.sched_setaffinity(tid, target)
        except OSError:  # a thread that has just exited, or a core we may not use
            pass
