"""CPU placement: a body worker and its controller on cores of their own.

A lockstep pair takes turns: the body steps its physics while the controller waits for the
next frame, then the controller computes while the body waits for its command. Left to the
scheduler, the two processes (and their Zenoh threads) move between cores on wake-ups and
start ticks with cold caches. Pinned to two different cores, each wakes where it slept: on the
2-core development machine a 10-s walker trial over Zenoh took 1.37-1.39x the one-process time
pinned, against 1.41-1.96x unpinned (``benchmarks/planar.py --pin always`` / ``never``).

Pinning is fragile when the pinned processes take every core. A pinned process cannot move to
the core its partner has left idle, so anything else that wants CPU (a Rerun viewer, another
run, one busy loop) competes with it for its core at every tick: with one busy loop beside it,
the same trial took 509 ms pinned against 210 ms unpinned. And with more lockstep processes
than cores (two body workers and two controller processes on two cores) a sweep ran 1.11x
faster with two workers, against 1.35-1.54x unpinned.

Nor can one run know which cores another run has pinned: two runs started side by side with
the same ``lockstep.pin_cpus`` would pin to the same cores and compete on them while other cores idle.

So the scenario's ``lockstep.pin_cpus`` is ``never`` by default, as in ROS 2 or dora, where pinning is the
user's call. ``auto`` gives the body workers and their controller processes one core each, in that
order, when a core is left over for everything else (the brain modules, the supervisor's logging,
a viewer); ``always`` whenever there are as many cores as lockstep processes (a machine kept for the
run). Both pin within the cores ``sfl run`` itself may use, so ``taskset -c 0-2 sfl run ...`` and
``taskset -c 3-5 sfl run ...`` keep two runs apart. Brain modules and the supervisor are never
pinned. Linux only (elsewhere a no-op).
"""

from __future__ import annotations

import os
from collections.abc import Iterable


def usable_cpus() -> list[int]:
    """The cores this process may run on (respects ``taskset`` and container limits); empty
    where the OS offers no CPU affinity (macOS, Windows), so that nothing is ever pinned there."""
    if hasattr(os, "sched_getaffinity"):
        return sorted(os.sched_getaffinity(0))
    return []


def assign(lockstep: list[str], cpus: list[int], mode: str) -> dict[str, list[int]]:
    """One core per lockstep process (``lockstep``: names in order) under ``lockstep.pin_cpus`` ``mode``,
    or none at all: with ``never``, with a single core, or with too few cores for the mode."""
    spare = {"auto": 1, "always": 0}.get(mode)
    if spare is None or len(cpus) < 2 or len(lockstep) + spare > len(cpus):
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
