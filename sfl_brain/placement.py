"""CPU placement: a body worker and its controller on different cores.

A lockstep pair takes turns: the body steps its physics while the controller waits for the
next frame, then the controller computes while the body waits for its command. Left to the
scheduler, the two processes (and their Zenoh threads) migrate between cores on every wake-up
and start each tick with cold caches. Pinned to two different cores, each wakes where it slept.
On the 2-core development machine this took a 10-s walker trial over Zenoh from 1.41-1.96x to
1.38-1.39x the one-process time (``benchmarks/planar.py`` prints both).

Pinning only helps when every lockstep process can have a core of its own. With more of them
than cores (two body workers and two controller processes on two cores), a pinned controller
must wait for the other pair's body to leave its core, and a sweep ran 1.11x faster with two
workers instead of 1.35-1.54x unpinned. So the scenario's ``pin_cpus`` (default true) pins the
body workers and their controller processes, one core each in that order, only when there are
enough usable cores for all of them; the brain modules and the supervisor are left to the
scheduler. Linux only (elsewhere a no-op).
"""

from __future__ import annotations

import os
from collections.abc import Iterable


def usable_cpus() -> list[int]:
    """The cores this process may run on (respects ``taskset`` and container limits)."""
    if hasattr(os, "sched_getaffinity"):
        return sorted(os.sched_getaffinity(0))
    return list(range(os.cpu_count() or 1))


def assign(lockstep: list[str], cpus: list[int]) -> dict[str, list[int]]:
    """One core per lockstep process (``lockstep``: names in order), or none at all if the
    cores are too few for that or there is nothing to separate."""
    if len(lockstep) > len(cpus) or len(cpus) < 2:
        return {}
    return {name: [cpu] for name, cpu in zip(lockstep, cpus, strict=False)}


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
