"""Lockstep ticks between a body and its controller in two processes, beside their physical floors.

    python benchmarks/bus.py [--ticks 1000] [--repeats 9] [--busy-repeats 7] [--block 50]
                             [--work-us 90] [--spin-us 200] [--no-startup] [--startup-repeats 5]

A tick: the body does ``--work-us`` of computation (its physics: a calibrated interpreter loop,
``_floor.py``), sends a sensor frame (240 bytes) and waits for the motor command (96 bytes). Every
variant runs ``--ticks`` ticks per round, in blocks of ``--block`` ticks taken in turn with every
other variant (interleaved finely, so that all see the same machine load); each figure is the
median over ``--repeats`` rounds of the variant's time over the one-process time of the same round.

(one process) the work, then the open-loop controller through ``InProcessLink``, on the core a pair gets;
(pipe) an OS pipe each way, both blocking: on two cores, and both on one core;
(shared memory) both spinning on a sequence number, not pinned;
(bare Zenoh) pub/sub, both blocking in a ring channel's recv(): on the run's mesh configuration
    (TCP) on two cores and on one core, and on the lockstep link's configuration (lowlatency
    transport, QoS off, a Unix socket; ``bus.tick_config``) on one core;
(socket) a Unix ``SOCK_SEQPACKET`` socket pair, both blocking, on one core: the transport of
    ``lockstep.link: socket`` (``sfl_brain.runtime.ticklink``), bare;
(typed by hand) bare Zenoh on the lockstep link, and the bare socket, with the framework's codec and the
    open-loop controller written by hand (no host, no link, no checks): what the messages cost, apart
    from the runtime;
(framework) the body's link to an open-loop controller hosted by ``sfl_brain.runtime.host``, typed, encoded,
    checked, dispatched: as ``sfl run`` runs a pair now (both on one core, blocking, ``SocketLink`` on
    their socket link), with ``lockstep.link: zenoh`` (``BusLink`` on a Zenoh lowlatency session), and
    as before issue 24 (not pinned, ticks on the mesh, the body polling up to ``--spin-us``);
then one process, the framework, bare Zenoh on the link, the bare socket and the spinning pair again beside
one busy process (a spinning process this benchmark starts, unpinned). Every session runs Zenoh's runtimes
on one thread (``bus.RUNTIME``). Then the ``sfl run`` start-up (five module processes) to the first
trial (``--no-startup``: skipped).
"""

from __future__ import annotations

import argparse
import functools
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _floor  # noqa: E402
from _common import HostedPair, Pinned  # noqa: E402

from sfl_brain.body import InProcessLink  # noqa: E402
from sfl_brain.messages import ControllerReset, SensorFrame  # noqa: E402
from sfl_brain.modules.controllers.open_loop import OpenLoopController  # noqa: E402
from sfl_brain.runtime import bus  # noqa: E402
from sfl_brain.runtime.placement import usable_cpus  # noqa: E402
from sfl_brain.runtime.ticklink import BusLink, SocketLink  # noqa: E402

SENSORS = ["hip_l", "hip_r", "knee_l", "knee_r", "contact_l", "contact_r", "slope", "pitch"]
COMMANDS = ["v_hip_l", "v_hip_r", "v_knee_l", "v_knee_r"]
#: the framework as ``sfl run`` runs a pair now
NOW = "framework now: socket link (lockstep.link: socket), one core"
RESET = ControllerReset(trial_id=0, seed=0, params={}, sensors=SENSORS, commands=COMMANDS)


class _Side:
    """The body's end of a lockstep pair: ``link`` (an ``InProcessLink`` or a ``BusLink``) stepped ``ticks`` times on
    ``mine`` (cores; None: not pinned), each tick's body work ``tick()`` first."""

    def run(self, ticks: int, tick) -> float:
        with Pinned(self.mine):
            step, values = self.link.step, self.values
            t = time.perf_counter()
            for _ in range(ticks):
                tick()
                step(SensorFrame(trial_id=0, tick=self.tick, values=values))
                self.tick += 1
            return time.perf_counter() - t


class OneProcess(_Side):
    """The body's work, then the open-loop controller through InProcessLink, on ``cores`` (the pair's core,
    so that both meet the same neighbours on a busy machine; None: not pinned)."""

    def __init__(self, cores=None) -> None:
        self.mine = cores
        self.link = InProcessLink(OpenLoopController())
        self.link.reset(RESET)
        self.values = np.zeros(len(SENSORS))
        self.tick = 0

    def close(self) -> None:
        pass


class Framework(_Side):
    """This process as the body: ``BusLink`` to an open-loop controller hosted by ``sfl_brain.runtime.host``,
    placed as ``lockstep.pin_cpus`` ``placement`` says, ticks on the lockstep ``link`` or the mesh."""

    def __init__(self, session, endpoint, run_id, folder, placement: str, link: str, spin: float) -> None:
        self.pair = HostedPair(
            session,
            endpoint,
            run_id,
            "sfl_brain.modules.controllers.open_loop:OpenLoopController",
            pin=placement,
            link=link,
            folder=folder,
        )
        self.mine = self.pair.placement.of("body")
        spin = 0.0 if self.mine else spin  # a body pinned with its controller never polls (it may use one core only)
        self.ticks = None
        if link == "socket":
            self.link = SocketLink(session, run_id, "body", "controller", 10.0, spin, endpoint=self.pair.tick)
        else:
            self.ticks = bus.open_tick_session([], [self.pair.tick]) if self.pair.tick else None
            self.link = BusLink(session, run_id, "body", "controller", 10.0, spin, ticks=self.ticks)
        self.link.reset(RESET)
        self.values = np.zeros(len(SENSORS))
        self.tick = 0

    def close(self) -> None:
        self.link.close()
        if self.ticks is not None:
            self.ticks.close()
        self.pair.close()


def startup(repeats: int = 5) -> dict[str, np.ndarray]:
    """``sfl run`` to all modules alive and to the first trial done, with the pair placed (``pin_cpus: auto``)
    and not (``never``), interleaved: (ready s, first trial s) per run."""
    from sfl_brain.runtime.run import run
    from sfl_brain.scenario import load

    root = Path(__file__).resolve().parents[1]
    times: dict[str, list] = {"auto": [], "never": []}
    for _ in range(repeats):
        for mode in times:
            sets = ["protocol.trials=1", "record.body_every=0", f"lockstep.pin_cpus={mode}"]
            plan = load(root / "scenarios" / "quickstart.yaml", sets)
            first = {}
            t0 = time.perf_counter()
            with tempfile.TemporaryDirectory() as tmp:
                run(
                    plan,
                    Path(tmp) / "run",
                    on_ready=lambda sup, s, f=first: f.setdefault("ready", s),
                    on_progress=lambda p, f=first, t0=t0: f.setdefault("trial", time.perf_counter() - t0),
                )
            times[mode].append((first["ready"], first["trial"]))
    return {mode: np.array(t) for mode, t in times.items()}


def rounds(sides: dict, reference: str, repeats: int, ticks: int, block: int, tick) -> dict[str, list[float]]:
    """Each side's time over the reference's, per round; the sides take blocks of ticks in turn, in a shuffled order."""
    ratios: dict[str, list[float]] = {name: [] for name in sides}
    order, shuffle = list(sides), np.random.default_rng(0).shuffle
    for _ in range(repeats):
        total = dict.fromkeys(sides, 0.0)
        for _ in range(max(ticks // block, 1)):
            shuffle(order)  # no variant always runs right after the same other one
            for name in order:
                total[name] += sides[name].run(block, tick)
        for name in sides:
            ratios[name].append(total[name] / total[reference])
    return ratios


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--ticks", type=int, default=1000, help="ticks per variant and round")
    parser.add_argument("--repeats", type=int, default=9, help="rounds")
    parser.add_argument("--busy-repeats", type=int, default=7, help="rounds beside one busy process")
    parser.add_argument("--block", type=int, default=50, help="ticks a variant runs before the next one's turn")
    parser.add_argument("--work-us", type=float, default=90.0, help="the body's work per tick (its physics)")
    parser.add_argument("--spin-us", type=float, default=200.0, help="lockstep.spin_us of the framework before")
    parser.add_argument("--no-startup", action="store_true", help="skip the sfl run start-up timing")
    parser.add_argument("--startup-repeats", type=int, default=5, help="sfl run start-ups per placement")
    args = parser.parse_args()
    cpus = usable_cpus()
    one = [cpus[-1]] if len(cpus) > 1 else None  # as lockstep.pin_cpus auto places a pair
    two = ([cpus[0]], [cpus[-1]]) if len(cpus) > 1 else (None, None)
    tick = functools.partial(_floor.work, _floor.calibrate(args.work_us))
    print(f"before: {_floor.machine_load()}", flush=True)
    endpoint = bus.free_endpoint()
    session = bus.open_session([endpoint], [])
    folder = tempfile.mkdtemp(prefix="sfl-")
    tmp = Path(folder)
    sides: dict = {"one process": OneProcess(one)}
    spin = args.spin_us * 1e-6
    try:
        sides["pipe, both block, two cores"] = _floor.Pair("pipe", 0, *two, tmp)
        sides["pipe, both block, one core"] = _floor.Pair("pipe", 0, one, one, tmp)
        sides["shared memory, both spin, not pinned"] = _floor.Pair("shm", 0, None, None, tmp)
        sides["bare Zenoh, mesh (tcp), both block, two cores"] = _floor.Pair("zenoh-mesh", 0, *two, tmp)
        sides["framework before: mesh, not pinned, body polls"] = Framework(
            session, endpoint, "benchbefore", folder, "never", "mesh", spin
        )
        sides["bare Zenoh, mesh (tcp), both block, one core"] = _floor.Pair("zenoh-mesh", 0, one, one, tmp)
        sides["bare Zenoh, lockstep link, both block, one core"] = _floor.Pair("zenoh-tick", 0, one, one, tmp)
        sides["  + typed messages and controller, by hand"] = _floor.Pair("zenoh-tick-typed", 0, one, one, tmp)
        sides["framework, Zenoh lockstep link (lockstep.link: zenoh), one core"] = Framework(
            session, endpoint, "benchzenoh", folder, "auto", "zenoh", spin
        )
        sides["socket (SOCK_SEQPACKET), both block, one core"] = _floor.Pair("socket", 0, one, one, tmp)
        sides["  + typed messages and controller, by hand "] = _floor.Pair("socket-typed", 0, one, one, tmp)
        sides[NOW] = Framework(session, endpoint, "benchnow", folder, "auto", "socket", spin)
        for side in sides.values():
            side.run(200, tick)  # warm up
        ratios = rounds(sides, "one process", args.repeats, args.ticks, args.block, tick)
        during = _floor.machine_load()
        busy_names = [
            "one process",
            "shared memory, both spin, not pinned",
            "bare Zenoh, lockstep link, both block, one core",
            "socket (SOCK_SEQPACKET), both block, one core",
            NOW,
        ]
        neighbour = _floor.Busy()
        try:
            busy = rounds(
                {n: sides[n] for n in busy_names}, "one process", args.busy_repeats, args.ticks, args.block, tick
            )
        finally:
            neighbour.close()
        beside = _floor.machine_load()
        reference = sides["one process"].run(args.ticks, tick) / args.ticks
    finally:
        for side in sides.values():
            side.close()
        session.close()
        shutil.rmtree(folder, ignore_errors=True)
    where = f"one core = core {one[0]}, two cores = {two[0][0]} and {two[1][0]}" if one else "nothing pinned (1 core)"
    print(
        f"lockstep tick: {args.work_us:g} us of body work, 240 B out, 96 B back; {args.ticks} ticks per round in "
        f"blocks of {args.block}; medians of {args.repeats} rounds, over one process in the same round "
        f"(one process: {reference * 1e6:.1f} us per tick); {where}; during: {during}"
    )
    width = max(map(len, ratios))
    for name, r in ratios.items():
        q1, q3 = np.percentile(r, [25, 75])
        print(f"  {name:<{width}}  {np.median(r):5.2f}  (IQR {q1:.2f}-{q3:.2f})")
    for label, raw_name, typed_name, framework_name in (
        (
            "framework / bare socket in the same configuration (socket link, one core)",
            "socket (SOCK_SEQPACKET), both block, one core",
            "  + typed messages and controller, by hand ",
            NOW,
        ),
        (
            "framework / bare Zenoh in the same configuration (Zenoh lockstep link, one core)",
            "bare Zenoh, lockstep link, both block, one core",
            "  + typed messages and controller, by hand",
            "framework, Zenoh lockstep link (lockstep.link: zenoh), one core",
        ),
    ):
        raw, typed, framework = (np.median(ratios[n]) for n in (raw_name, typed_name, framework_name))
        print(
            f"  {label}: {framework / raw:.2f} (goal <= 1.10); the framework adds "
            f"{(framework - raw) * reference * 1e6:.1f} us per tick, of which the typed messages and the "
            f"controller's step by hand {(typed - raw) * reference * 1e6:.1f} us"
        )
    print(f"beside one busy process: medians of {args.busy_repeats} rounds; {beside}")
    for name, r in busy.items():
        q1, q3 = np.percentile(r, [25, 75])
        print(f"  {name:<{width}}  {np.median(r):5.2f}  (IQR {q1:.2f}-{q3:.2f})")
    if args.no_startup:
        return
    started = startup(args.startup_repeats)
    for mode, s in started.items():
        print(
            f"sfl run start-up, 5 module processes, lockstep.pin_cpus {mode}: all alive {np.median(s[:, 0]):.2f} s, "
            f"first trial done {np.median(s[:, 1]):.2f} s (median of {len(s)}, interleaved; goal <= 2 s)"
        )
    print(f"after: {_floor.machine_load()}")


if __name__ == "__main__":
    main()
