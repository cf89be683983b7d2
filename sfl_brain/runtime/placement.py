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
  controller process share a core of their own, the least busy one (:func:`core_load`, measured for
  :data:`MEASURE_S` before anything starts: what other processes keep each core busy with; the last
  usable core among equals); the brain modules are pinned to the cores no pair has and nothing else
  keeps busy, when there are any (they work between trials, while the pairs wait). A core that other
  work keeps busy more than :data:`BUSY` of the time is no place for a pair: pinned there, the pair
  could not move to a core with room, and would get its share of the busy one only. With no quiet
  core for each pair, or more pairs than cores, nothing is pinned: the scheduler spreads them better
  than a fixed share would. While the run goes on, the supervisor looks again every
  :data:`RECHECK_S` s (:class:`CoreWatch`): a pair's core that other work has come to keep busy makes
  the placement yield, the pair moving to a quiet core or, with none, every process unpinned.
* ``always``: each pair on a core of its own whatever else runs there (the last usable core first,
  as ``auto`` did before issue 34), and with more pairs than cores the pairs share the cores in turn.
* ``never``: nothing is pinned (two runs side by side without ``taskset``, whose pairs would
  otherwise pick the same core; a machine where something else is pinned to the last cores).

On one core, where the OS offers no CPU affinity (macOS, Windows), or when every controller runs
inside its body worker (``colocate: true``: no pair to place), nothing is pinned. The supervisor
itself is never pinned. ``taskset -c 0-2 sfl run ...`` and ``taskset -c 3-5 sfl run ...`` keep two
runs on cores of their own.
"""

from __future__ import annotations

import errno
import os
import random
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

#: lockstep.pin_cpus values
MODES = ("never", "auto", "always")

#: a core that other work keeps busy more than this fraction of the time gets no pair (``auto``)
BUSY = 0.5

#: s that :func:`core_load` watches the cores before a run places its processes
MEASURE_S = 0.3

#: s between two looks at the pairs' cores while a run goes on (:class:`CoreWatch`)
RECHECK_S = 5.0


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
    #: what other work kept each usable core busy with when the placement was made (fraction of the time)
    load: dict[int, float] = field(default_factory=dict)

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
            "load": {str(core): round(busy, 3) for core, busy in self.load.items()},
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


def place(
    pairs: list[Pair], others: list[str], cpus: list[int], mode: str, load: Mapping[int, float] | None = None
) -> Placement:
    """Where each lockstep pair and the other module processes (``others``: brain modules, colocated
    body workers) run, on the usable ``cpus``, under ``lockstep.pin_cpus`` ``mode``, given what other work
    keeps each core busy with (``load``: fraction of the time by core, from :func:`core_load`; none: quiet
    cores). Pure: the same arguments give the same placement."""
    if mode not in MODES:
        raise ValueError(f"lockstep.pin_cpus must be one of {MODES} (got {mode!r})")
    usable = tuple(sorted(cpus))
    load = {core: float(load.get(core, 0.0)) for core in usable} if load else {}
    paired = [p for p in pairs if p.controller is not None]

    def unpinned(why: str) -> Placement:
        return Placement(mode, usable, {}, f"nothing pinned: {why}", load)

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
    if mode == "always":
        order = list(usable[::-1])
    else:  # the least busy first (to a tenth; the last core among equals)
        order = sorted(usable, key=lambda core: (round(load.get(core, 0.0), 1), -core))
        if any(load.get(core, 0.0) > BUSY for core in order[: len(paired)]):
            said = ", ".join(f"core {core} {busy:.0%}" for core, busy in sorted(load.items()))
            return unpinned(
                f"other work keeps the cores busy ({said} of the time): a pair pinned to one could not move to "
                "a core with room, so the scheduler places every process"
            )
    cores: dict[str, tuple[int, ...]] = {}
    said = []
    for i, pair in enumerate(paired):
        core = order[i % len(order)]
        cores[pair.body] = cores[pair.controller] = (core,)
        said.append(f"{pair.body} and {pair.controller} share core {core}")
    taken = {core for (core,) in cores.values()}
    rest = tuple(c for c in usable if c not in taken and (mode == "always" or load.get(c, 0.0) <= BUSY))
    if others and rest:
        for name in others:
            cores[name] = rest
        said.append(f"{', '.join(others)} on {'core' if len(rest) == 1 else 'cores'} {cpu_list(rest)}")
    elif others:
        left = "no core left" if len(taken) == len(usable) else "the other cores are kept busy by other work"
        said.append(f"{', '.join(others)} not pinned ({left})")
    if load and mode == "auto" and any(busy > 0.05 for busy in load.values()):
        said.append("other work on " + ", ".join(f"core {c} {b:.0%}" for c, b in sorted(load.items())))
    return Placement(mode, usable, cores, "; ".join(said), load)


def _cpu_times() -> dict[int, tuple[float, float]]:
    """(busy, total) seconds of each core since boot, from ``/proc/stat`` (empty where there is none)."""
    tick = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100
    times = {}
    try:
        with open("/proc/stat", "rb") as f:
            lines = f.read().splitlines()
    except OSError:
        return {}
    for line in lines:
        if not line.startswith(b"cpu") or line.startswith(b"cpu "):
            continue
        name, *fields = line.split()
        values = [int(v) for v in fields[:8]]  # user nice system idle iowait irq softirq steal
        idle = values[3] + values[4]
        times[int(name[3:])] = ((sum(values) - idle) / tick, sum(values) / tick)
    return times


def core_load(cpus: Iterable[int], seconds: float = MEASURE_S) -> dict[int, float]:
    """What keeps each of ``cpus`` busy now: the fraction of ``seconds`` it was not idle (every process on it, this
    one too); empty where the OS does not say (no ``/proc/stat``)."""
    before = _cpu_times()
    if not before:
        return {}
    time.sleep(seconds)  # a measurement over an interval: nothing to wait for
    after = _cpu_times()
    load = {}
    for core in cpus:
        if core in before and core in after:
            busy, total = (a - b for a, b in zip(after[core], before[core], strict=True))
            load[core] = min(1.0, max(0.0, busy / total)) if total > 0 else 0.0
    return load


class CoreWatch:
    """What other work keeps each core busy with while a run goes on: the cores' busy time (``/proc/stat``) less
    the CPU time the run's own processes used on them, over the last :data:`RECHECK_S` s or more.

    ``sample(used)`` with the run's CPU seconds so far by core (its processes pinned there); every
    :data:`RECHECK_S` s it returns the load by core over the stretch since the last answer, else None."""

    def __init__(self, cpus: Iterable[int]) -> None:
        self.cpus = tuple(cpus)
        self._since: float | None = None
        self._cores: dict[int, tuple[float, float]] = {}
        self._used: dict[int, float] = {}

    def due(self) -> bool:
        """Whether :meth:`sample` would answer now (or start): the run's CPU by core is only worth reading then."""
        return self._since is None or time.monotonic() - self._since >= RECHECK_S

    def sample(self, used: Mapping[int, float]) -> dict[int, float] | None:
        now = time.monotonic()
        cores = _cpu_times()
        if not cores:
            return None
        if self._since is None:
            self._since, self._cores, self._used = now, cores, dict(used)
            return None
        if now - self._since < RECHECK_S:
            return None
        load = {}
        for core in self.cpus:
            if core not in cores or core not in self._cores:
                continue
            busy, total = (a - b for a, b in zip(cores[core], self._cores[core], strict=True))
            ours = used.get(core, 0.0) - self._used.get(core, 0.0)
            load[core] = min(1.0, max(0.0, (busy - ours) / total)) if total > 0 else 0.0
        self._since, self._cores, self._used = now, cores, dict(used)
        return load


def keep_nice_in_own_session() -> int | None:
    """Carry this process's nice level to its session's scheduling group; returns the level written, or None.

    Every module host is a session of its own (``setsid``: Ctrl-C reaches the supervisor only). Where the kernel
    groups the CPU's shares by session (autogroup, on by default in many Linux distributions), a session competes with
    the others at its group's nice, 0 when it is created, whatever its processes' own: ``nice -n 10 sfl run`` would
    then starve nothing of the machine's other work. Raising one's own group's nice needs no privilege; lowering it
    is never asked here. Only a session's leader does it (a module host started by the runtime), never a process in
    someone else's session (``sfl worker`` in a terminal would nice the whole terminal). Nothing is done where there
    is no autogroup (macOS, Windows, kernels without it)."""
    if not hasattr(os, "getpriority") or os.getsid(0) != os.getpid():
        return None
    level = min(os.getpriority(os.PRIO_PROCESS, 0), 19)
    if level <= 0:
        return None
    # without CAP_SYS_ADMIN the kernel takes one such write per 100 ms, machine-wide (EAGAIN): the run's hosts start
    # together, so each tries again for up to 3 s
    deadline = time.monotonic() + 3.0
    while True:
        try:
            with open("/proc/self/autogroup", "w") as group:
                group.write(str(level))
            return level
        except OSError as error:  # no autogroup, or refused: the process's own nice still holds within its group
            if error.errno != errno.EAGAIN or time.monotonic() > deadline:
                return None
            time.sleep(0.11 + 0.05 * random.random())


def usable_cpus() -> list[int]:
    """The cores this process may run on (respects ``taskset`` and container limits); empty
    where the OS offers no CPU affinity (macOS, Windows), so that nothing is ever pinned there."""
    if hasattr(os, "sched_getaffinity"):
        return sorted(os.sched_getaffinity(0))
    return []


def pin_process(pid: int, cpus: Iterable[int]) -> bool:
    """Move every thread of process ``pid`` (another of this user's) onto ``cpus``; False if it is gone."""
    if not hasattr(os, "sched_setaffinity"):
        return False
    target = set(cpus)
    try:
        threads = [int(t) for t in os.listdir(f"/proc/{pid}/task")]
    except OSError:
        threads = [pid]
    moved = False
    for tid in threads:
        try:
            os.sched_setaffinity(tid, target)
            moved = True
        except OSError:  # a thread that has just exited
            pass
    return moved


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
