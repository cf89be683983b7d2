"""Liveness by progress: is a module process working, denied the CPU, stopped, or hung?

A busy machine makes a run slower, never kills it. So a module process on this machine is not judged by the
wall clock or by a network lease but by two things the supervisor can see:

* **progress**: each host counts what it gets done (requests answered, lockstep ticks handled or stepped) in its
  slot of the run's :class:`ProgressBoard`, a small shared file the supervisor reads (and the body reads its
  controller's);
* **the CPU it was offered**: from ``/proc/<pid>/stat`` (state) and ``/proc/<pid>/task/*/schedstat`` (CPU time and
  *run delay*, the time its threads were ready to run and waited for a core) of each thread, sampled while the run
  waits on the process.

:class:`NoProgressClock` adds up, between two samples of a group of processes (a body worker and its controller
process take turns, so they are judged as one), the time the group could have run: the interval less the time its
threads waited for a core, and none of it while a member is stopped (SIGSTOP, a suspended laptop: ``T``) or in an
uninterruptible wait on the machine (``D``). Progress sets it back to zero. A group whose clock passes its limit
(``timeouts.ready``, ``request``, ``trial``, ``tick``) had the CPU all that time and did nothing with it: it is
hung. A process that is starved, niced, stopped and continued, or waits on the disk is waited for, however long.

Where ``/proc`` has no ``schedstat`` (a kernel without scheduler statistics; not Linux) the clock counts the CPU
time the group actually used (``psutil``), so a busy loop is still found; a process that sleeps forever is not.

Nothing here imports Zenoh.
"""

from __future__ import annotations

import mmap
import os
import struct
import time
from dataclasses import dataclass
from pathlib import Path

#: bytes of a process's slot on the board: its pid, then what it got done (two unsigned 64-bit integers)
SLOT = struct.Struct("<QQ")

#: longest stretch between two samples that counts: a supervisor (or body) that was itself stopped or starved for
#: longer did not see what happened meanwhile, and counts nothing against the processes it watches for that time
MAX_INTERVAL = 2.0

#: process states (``/proc/<pid>/stat``) in which a process cannot run: stopped, traced, in an uninterruptible wait
HELD = frozenset("TtD")


class ProgressBoard:
    """The run's progress board: one :data:`SLOT` per module process, in a file of the run's private folder, which
    the supervisor creates and every host maps (:class:`ProgressSlot`). Reading a slot is a read of 16 bytes."""

    FILE = "progress"

    def __init__(self, folder: str | Path, names: list[str]) -> None:
        self.path = Path(folder) / self.FILE
        self.slots = {name: i for i, name in enumerate(names)}
        self.path.write_bytes(bytes(SLOT.size * max(1, len(names))))
        self._file = open(self.path, "rb")  # noqa: SIM115 - kept for the run
        self._map = mmap.mmap(self._file.fileno(), 0, access=mmap.ACCESS_READ)

    def read(self, name: str) -> tuple[int, int]:
        """(pid, progress) of process ``name`` as its host last wrote them (0, 0 before it started)."""
        return SLOT.unpack_from(self._map, SLOT.size * self.slots[name])

    def spec(self, name: str) -> dict:
        """What a host needs to write its slot: ``{"path": ..., "slot": i}``."""
        return {"path": str(self.path), "slot": self.slots[name]}

    def close(self) -> None:
        self._map.close()
        self._file.close()


class ProgressSlot:
    """A host's slot on the board: it writes its pid once and bumps its count for every request answered and every
    lockstep tick (a write to shared memory, no system call). Also reads another slot (a body its controller's). It
    stays mapped until the process exits: a lockstep thread still returning may count a tick."""

    def __init__(self, path: str | Path, slot: int) -> None:
        self._file = open(path, "r+b")  # noqa: SIM115 - kept while the host serves
        self._map = mmap.mmap(self._file.fileno(), 0)
        self._offset = SLOT.size * slot
        self._count = memoryview(self._map)[self._offset + 8 : self._offset + 16].cast("Q")
        SLOT.pack_into(self._map, self._offset, os.getpid(), 0)

    def bump(self) -> None:
        """One more thing done (a request answered, a tick handled)."""
        self._count[0] += 1

    def pid_of(self, slot: int) -> int:
        """The pid written in ``slot`` (0 before its process started)."""
        return SLOT.unpack_from(self._map, SLOT.size * slot)[0]


@dataclass(frozen=True)
class CpuSample:
    """What one process was doing at ``at`` (``time.monotonic``): its ``state`` (``R``, ``S``, ``D``, ``T``...), the
    CPU seconds its threads used, and the seconds they waited, ready, for a core (None where unknown)."""

    at: float
    state: str
    cpu: float
    waited: float | None


def _schedstat(pid: int) -> tuple[float, float] | None:
    """(CPU seconds, run-delay seconds) summed over every thread of ``pid``; None without scheduler statistics."""
    cpu = waited = 0
    try:
        threads = os.listdir(f"/proc/{pid}/task")
    except OSError:
        return None
    for tid in threads:
        try:
            with open(f"/proc/{pid}/task/{tid}/schedstat", "rb") as f:
                fields = f.read().split()
        except OSError:  # a thread that has just exited
            continue
        cpu += int(fields[0])
        waited += int(fields[1])
    return cpu * 1e-9, waited * 1e-9


def _has_schedstat() -> bool:
    return os.path.exists(f"/proc/{os.getpid()}/schedstat")


#: where the run delay can be read (Linux with scheduler statistics)
SCHEDSTAT = _has_schedstat()


def cpu_sample(pid: int) -> CpuSample | None:
    """How process ``pid`` is doing now; None once it is gone."""
    now = time.monotonic()
    if SCHEDSTAT:
        try:
            with open(f"/proc/{pid}/stat", "rb") as f:
                stat = f.read()
        except OSError:
            return None
        state = stat[stat.rindex(b")") + 2 : stat.rindex(b")") + 3].decode()
        times = _schedstat(pid)
        if times is None or state in ("Z", "X"):
            return None
        return CpuSample(now, state, times[0], times[1])
    try:  # no run delay here: the CPU it used, and whether it is stopped
        import psutil

        proc = psutil.Process(pid)
        with proc.oneshot():
            status, used = proc.status(), proc.cpu_times()
    except Exception:  # psutil missing, or the process gone
        return None
    if status in (psutil.STATUS_ZOMBIE, psutil.STATUS_DEAD):
        return None
    state = {psutil.STATUS_STOPPED: "T", psutil.STATUS_DISK_SLEEP: "D"}.get(status, "R")
    return CpuSample(now, state, used.user + used.system, None)


def had_the_cpu(before: list[CpuSample], after: list[CpuSample]) -> float:
    """Seconds that a group of processes (sampled ``before`` and ``after``, in the same order) could have run between
    the two samples: none while one of them was stopped or in an uninterruptible wait, else the interval less the time
    its threads waited for a core (without run delays: the CPU time they used). At most :data:`MAX_INTERVAL`."""
    if not before or len(before) != len(after):
        return 0.0
    interval = max(0.0, max(a.at for a in after) - min(b.at for b in before))
    if interval <= 0 or any(s.state in HELD for s in (*before, *after)):
        return 0.0
    counted = min(interval, MAX_INTERVAL)
    if all(s.waited is not None for s in (*before, *after)):
        waited = sum(a.waited - b.waited for a, b in zip(after, before, strict=True))
        return counted * max(0.0, 1.0 - waited / interval)
    used = sum(a.cpu - b.cpu for a, b in zip(after, before, strict=True))
    return min(counted, used * counted / interval)


class NoProgressClock:
    """Seconds a group of processes had the CPU since it last made progress (:mod:`sfl_brain.runtime.liveness`).

    ``update(samples, marks)`` with the group's samples and what it has done so far (any value that changes with
    progress); the answer is the time it had the CPU since ``marks`` last changed. ``used`` says how much CPU time
    each member used meanwhile (which of them spins)."""

    def __init__(self) -> None:
        self.seconds = 0.0
        self._marks: object = None
        self._last: list[CpuSample] | None = None
        self._first: list[CpuSample] | None = None

    def update(self, samples: list[CpuSample | None], marks: object) -> float:
        if any(s is None for s in samples):  # a member is gone: its exit decides, not this clock
            self.reset()
            return 0.0
        if marks != self._marks or self._last is None or len(self._last) != len(samples):
            self._marks, self._last, self._first, self.seconds = marks, samples, samples, 0.0
            return 0.0
        self.seconds += had_the_cpu(self._last, samples)
        self._last = samples
        return self.seconds

    def used(self) -> list[float]:
        """CPU seconds each member used since the last progress."""
        if self._first is None or self._last is None:
            return []
        return [b.cpu - a.cpu for a, b in zip(self._first, self._last, strict=True)]

    def reset(self) -> None:
        self.seconds, self._marks, self._last, self._first = 0.0, None, None, None
