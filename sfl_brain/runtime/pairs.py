"""The run's lockstep pairs on this machine: which processes take turns, the tick link each pair gets, the cores
every process runs on (``logs/placement.json``) and how that placement yields to other work while the run goes on.

A body worker and its controller process exchange a message every control tick; :func:`lockstep_pairs` finds them in
the plan, :func:`.placement.place` decides their cores, and :class:`Pairs` keeps what was decided for the
:class:`~.supervisor.Supervisor`, which hands each process its cores and its end of the link at its spawn.
"""

from __future__ import annotations

import json
import logging
import os
import socket
from collections.abc import Mapping
from pathlib import Path

from ..events import Events, PlacementYielded
from ..messages import SensorFrame
from ..scenario.plan import Plan
from . import bus, ticklink
from .liveness import cpu_sample
from .placement import BUSY, CoreWatch, Pair, Placement, core_load, pin_process, place, usable_cpus
from .processes import Child

log = logging.getLogger("sfl.runtime")

#: the longest path of a Unix socket, with its final NUL (Linux 108, macOS 104: the shorter)
UNIX_PATH_MAX = 104


def lockstep_pairs(plan: Plan) -> tuple[list[Pair], list[str]]:
    """The run's lockstep pairs (each body worker and its controller process, None when the controller
    is colocated or there is none) and its other module processes (brain modules)."""
    by_name = {i.name: i for i in plan.instances}
    pairs = []
    for body in plan.bodies:
        controller = by_name[body].routes.get(SensorFrame.TAG)
        pairs.append(Pair(body, controller if controller in by_name else None))
    paired = {name for p in pairs for name in (p.body, p.controller)}
    return pairs, [i.name for i in plan.instances if i.name not in paired]


def initial_placement(plan: Plan) -> Placement:
    """The run's placement (:func:`.placement.place`) on the cores it may use; with ``pin_cpus: auto`` and
    a pair to place on more than one core, after measuring what other work keeps each core busy with."""
    pairs, others = lockstep_pairs(plan)
    mode, cpus = plan.scenario.lockstep.pin_cpus, usable_cpus()
    measure = mode == "auto" and len(cpus) > 1 and any(p.controller is not None for p in pairs)
    return place(pairs, others, cpus, mode, core_load(cpus) if measure else None)


class Pairs:
    """Where the run's processes run: the placement on cores (measured when made), each pair's tick link, and the
    look at the pairs' cores that makes the placement yield (``pin_cpus: auto``)."""

    def __init__(self, plan: Plan, run_dir: Path, events: Events) -> None:
        self.plan = plan
        self.run_dir = run_dir
        self.events = events
        #: each body worker and its controller process on a core of their own, as lockstep.pin_cpus says
        self.placement: Placement = initial_placement(plan)
        #: what other work keeps the pairs' cores busy with while the run goes on (``auto``: the placement yields)
        self._core_watch = CoreWatch(self.placement.usable) if self.placement.mode == "auto" else None
        #: each paired process's end of its lockstep link (``listen`` or ``connect``), by name
        self.ticks: dict[str, dict[str, list[str]]] = {}
        self._ticks_on = ""

    def link(self, folder: str) -> None:
        """Give each body worker and its controller process their lockstep link (a socket in ``folder``), and say
        where every process runs: ``logs/placement.json`` and one line on the terminal."""
        pairs, _ = lockstep_pairs(self.plan)
        pairs = [p for p in pairs if p.controller is not None]
        links = "the mesh (no Unix sockets here)"
        if pairs and hasattr(socket, "AF_UNIX") and os.name != "nt":  # Zenoh has no unixsock-stream on Windows
            if len(os.fsencode(folder)) + len(f"/{len(pairs)}.sock") < UNIX_PATH_MAX:
                on_socket = self.plan.scenario.lockstep.link == "socket" and ticklink.available()
                endpoint_of = ticklink.endpoint if on_socket else bus.tick_endpoint
                for i, pair in enumerate(pairs):
                    endpoint = endpoint_of(folder, str(i))
                    self.ticks[pair.controller] = {"listen": [endpoint]}
                    self.ticks[pair.body] = {"connect": [endpoint]}
                kind = "Unix sockets" if on_socket else "Zenoh lowlatency sessions"
                if self.plan.scenario.lockstep.link == "socket" and not on_socket:
                    kind += " (lockstep.link: socket needs SOCK_SEQPACKET Unix sockets, which this OS lacks)"
                links = f"lockstep links ({kind}) in {folder}"
            else:
                links = f"the mesh (the temporary folder {folder} is too long a path for a Unix socket)"
        self._ticks_on = links
        self.write()
        log.info("%s; ticks on %s", self.placement.describe(), links)
        if pairs:
            print(f"sfl: {self.placement.describe()}", flush=True)

    def write(self) -> None:
        """``logs/placement.json``: where each process runs now, and each placement before it (``earlier``)."""
        path = self.run_dir / "logs" / "placement.json"
        earlier = []
        if path.exists():
            try:
                old = json.loads(path.read_text())
                earlier = old.pop("earlier", []) + [{k: old[k] for k in ("cores", "reason", "load") if k in old}]
            except (OSError, ValueError):
                earlier = []
        placed = self.placement.to_json() | {"lockstep_links": self.ticks, "ticks_on": self._ticks_on}
        path.write_text(json.dumps(placed | ({"earlier": earlier} if earlier else {}), indent=1) + "\n")

    def yield_cores(self, children: Mapping[str, Child]) -> None:
        """``pin_cpus: auto``: every :data:`.placement.RECHECK_S` s, what other work keeps each core busy
        with (the cores' busy time less this run's pinned processes'); a pair's core busier than
        :data:`.placement.BUSY` makes the placement yield: placed again on the load now (the pair moves to a
        quiet core, or nothing stays pinned), every process moved, and the user told."""
        watch = self._core_watch
        if watch is None or not self.placement.cores or not watch.due():
            return
        used: dict[int, float] = {}
        for name, cores in self.placement.cores.items():
            child = children.get(name)
            sample = cpu_sample(child.proc.pid) if child is not None and child.proc is not None else None
            if sample is not None and len(cores) == 1:
                used[cores[0]] = used.get(cores[0], 0.0) + sample.cpu
        load = watch.sample(used)
        pairs, others = lockstep_pairs(self.plan)
        paired = {n for p in pairs if p.controller is not None for n in (p.body, p.controller)}
        pair_cores = {c for name, cores in self.placement.cores.items() if name in paired for c in cores}
        trapped = sorted(c for c in pair_cores if load is not None and load.get(c, 0.0) > BUSY)
        if not trapped:
            return
        before = self.placement
        self.placement = place(pairs, others, list(before.usable), before.mode, load)
        for name, child in children.items():
            if child.proc is not None and before.of(name) != self.placement.of(name):
                pin_process(child.proc.pid, self.placement.of(name) or before.usable)
        busy = ", ".join(f"core {c} {load[c]:.0%}" for c in trapped)
        self.events.publish(PlacementYielded(busy, self.placement.describe()))
        self.write()
