"""Wall time of one 10-s trial (``--seconds``) of the planar walker, in one process and over processes, beside its
floors.

    python benchmarks/planar.py [--repeats 21] [--busy-repeats 15] [--seconds 10] [--grid 15] [--spin-us 200]
                                [--pin auto|always|never] [--no-sweep]

Every variant runs once per round, one after the other in a shuffled order (interleaved, so that all
see the same machine load), for ``--repeats`` rounds; a time is a median over the rounds, a ratio the
median of the ratios within each round. The load average is printed.

(a) physics only, fixed open-loop command; (b) reflexive controller and body in one process; both on
    the core (c) places its pair on, so that both meet the same neighbours on a busy machine;
(b0) the same with the body as it stepped before its hot path was batched (``_planar_before.py``),
    with the same metrics bit for bit (checked on every repeat);
(c) controller and body each hosted in its own process by ``sfl_brain.runtime.host``, as ``sfl run`` hosts
    them: placed as ``lockstep.pin_cpus`` ``--pin`` says (default ``auto``: both on one core), their
    frames and commands on their socket link (``lockstep.link: socket``); the trial is a request
    from this process, timed from request to reply;
(c-hand) (c) without the framework: the trial run in this process, the reflex controller in a child process
    on the pair's core, over a bare socket, the framework's messages written by hand (``_floor.HandLink``): no
    host, no nonce, no checks; (c)/(c-hand) is what the framework's runtime costs;
(c-zenoh) the pair placed as (c), its ticks on a Zenoh lowlatency session (``lockstep.link: zenoh``);
(c-free) the pair not pinned (``pin_cpus: never``), the body polling up to ``--spin-us`` for
    each command (``lockstep.spin_us``), on the Zenoh link: the placement before issue 24;
(c-mesh) the pair placed as (c), but its frames and commands on the run's mesh;
(c-apart) the pair on a core each (as ``pin_cpus: always`` placed it before issue 24), the body
    polling, on the Zenoh link;
then the floors of a lockstep pair whose body steps (a)'s physics each tick and whose controller answers at
once (``_floor.py``), against (a): a pipe and a bare ``SOCK_SEQPACKET`` socket, both on the pair's core;
shared memory, both spinning, not pinned; bare Zenoh on the lockstep link's configuration, both on the
pair's core: each link's baseline (framework / bare transport = ((c)/(b)) / (socket/(a)), and the same
of (c-zenoh) over bare Zenoh);
then (a), (b), (c), (c-zenoh), the bare socket, bare Zenoh and the spinning pair again beside one busy
process (a process this benchmark starts, spinning, unpinned);
then a sweep of a grid x grid subset of the E3.1 grid with 1 and with 2 body workers, with the
controllers colocated in the body workers and as separate processes (``--no-sweep``: skipped).
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
from _planar_before import PlanarBipedBefore  # noqa: E402

from sfl_brain.bodies.planar_biped import PlanarBiped  # noqa: E402
from sfl_brain.body import InProcessLink  # noqa: E402
from sfl_brain.messages import TrialRequest  # noqa: E402
from sfl_brain.modules.controllers.reflex import ReflexController  # noqa: E402
from sfl_brain.runtime import bus  # noqa: E402
from sfl_brain.runtime.host import request  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SECONDS = 10.0  # a trial's length: the walker's own (``duration``); ``--seconds`` shortens it for a smoke test
TICKS = 1000  # its control ticks
REQUEST = TrialRequest(
    trial_id=0,
    seed=0,
    body_params={"slope_deg": 0.0},
    controller_params={"alpha_hip": 10.0, "theta_hip_max_deg": 110.0},
    log=False,
)
BODY = "sfl_brain.bodies.planar_biped:PlanarBiped"
CONTROLLER = "sfl_brain.modules.controllers.reflex:ReflexController"


class ByHand:
    """(c-hand): (c)'s trial run here, its controller in a child process on the pair's core over a bare socket with
    the framework's messages written by hand (``_floor.HandLink``): (c) less the framework's runtime."""

    def __init__(self, cores) -> None:
        self.cores = cores
        self.body = walker()
        self.body.link = self.link = _floor.HandLink(CONTROLLER, cores)

    def trial(self) -> tuple[float, dict]:
        with Pinned(self.cores):
            t = time.perf_counter()
            result = self.body.handle(REQUEST)
            elapsed = time.perf_counter() - t
        assert result.metrics["time"] >= SECONDS - 0.01, result
        return elapsed, {"success": result.success, "quality": result.quality, **result.metrics}

    def close(self) -> None:
        self.link.close()


def walker(body_class=PlanarBiped) -> PlanarBiped:
    """The walker whose trial lasts ``SECONDS``."""
    return body_class(body_class.Params(duration=SECONDS))


def physics_tick():
    """One control tick of the walker's physics with a fixed open-loop command, on a freshly started trial:
    (a)'s work, and the body's work of every floor."""
    body = walker()
    body.logging = False
    body.start_trial(REQUEST)
    return functools.partial(body.actuate, np.array([1.0, -1.0, 0.5, 0.5]))


def physics_only() -> float:
    tick = physics_tick()
    t = time.perf_counter()
    for _ in range(TICKS):
        tick()
    return time.perf_counter() - t


def one_process(body_class=PlanarBiped) -> tuple[float, dict]:
    body = walker(body_class)
    body.link = InProcessLink(ReflexController())
    t = time.perf_counter()
    result = body.handle(REQUEST)
    elapsed = time.perf_counter() - t
    assert result.metrics["time"] >= SECONDS - 0.01, result
    return elapsed, {"success": result.success, "quality": result.quality, **result.metrics}


class Processes(HostedPair):
    """(c): the walker and the reflex controller hosted as sfl run hosts them; a trial is a request from here."""

    def __init__(self, session, endpoint, run_id, folder, **placed) -> None:
        super().__init__(
            session, endpoint, run_id, CONTROLLER, BODY, folder=folder, body_params={"duration": SECONDS}, **placed
        )
        self.session, self.key = session, bus.key(run_id, "body", TrialRequest.TAG)

    def trial(self) -> float:
        t = time.perf_counter()
        result = request(self.session, self.key, REQUEST, 60.0)
        elapsed = time.perf_counter() - t
        assert result.metrics["time"] >= SECONDS - 0.01, result
        return elapsed


def sweep(workers: int, grid: int, colocate: bool, lockstep: list[str]) -> float:
    from sfl_brain.runtime.run import run
    from sfl_brain.scenario import load

    plan = load(
        ROOT / "scenarios" / "e3_1_viability.yaml",
        [
            f"modules.body.workers={workers}",
            f"space.0.steps={grid}",
            f"space.1.steps={grid}",
            "record.body_every=0",
            f"modules.controller.colocate={str(colocate).lower()}",
            *lockstep,
        ],
    )
    with tempfile.TemporaryDirectory() as tmp:
        t = time.perf_counter()
        _, summary = run(plan, Path(tmp) / "run")
        assert summary["status"] == "completed", summary
        return time.perf_counter() - t


def median(samples) -> float:
    return float(np.median(samples))


def main() -> None:
    global SECONDS, TICKS
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeats", type=int, default=21, help="rounds")
    parser.add_argument("--busy-repeats", type=int, default=15, help="rounds beside one busy process")
    parser.add_argument("--seconds", type=float, default=SECONDS, help="a trial's simulated length (s)")
    parser.add_argument("--grid", type=int, default=15)
    parser.add_argument("--spin-us", type=float, default=200.0, help="lockstep.spin_us")
    parser.add_argument("--pin", choices=["auto", "always", "never"], default="auto", help="lockstep.pin_cpus of (c)")
    parser.add_argument("--no-sweep", action="store_true", help="skip the sweeps")
    args = parser.parse_args()
    SECONDS, TICKS = args.seconds, int(round(args.seconds * 100))
    spin = args.spin_us * 1e-6
    print(f"before: {_floor.machine_load()}", flush=True)
    endpoint = bus.free_endpoint()
    session = bus.open_session([endpoint], [])
    folder = tempfile.mkdtemp(prefix="sfl-")
    runs: dict[str, list[float]] = {}
    busy: dict[str, list[float]] = {}
    hosted: dict[str, Processes] = {}
    floors: dict[str, _floor.Pair] = {}
    by_hand: ByHand | None = None
    try:
        hosted["c"] = Processes(session, endpoint, "benchplanar", folder, pin=args.pin, spin=spin)
        hosted["c-zenoh"] = Processes(session, endpoint, "benchplanarzenoh", folder, pin=args.pin, link="zenoh")
        hosted["c-free"] = Processes(session, endpoint, "benchplanarfree", folder, pin="never", link="zenoh", spin=spin)
        hosted["c-mesh"] = Processes(session, endpoint, "benchplanarmesh", folder, pin=args.pin, link="mesh", spin=spin)
        hosted["c-apart"] = Processes(
            session, endpoint, "benchplanarapart", folder, pin="apart", link="zenoh", spin=spin
        )
        for pair in hosted.values():
            pair.trial()  # warm up
        # the floors: the body steps the walker's physics each tick, as (a), and the controller answers at once
        core = hosted["c"].placement.of("body")  # the pair's core (None: not pinned)
        floors["pipe"] = _floor.Pair("pipe", 0, core, core, Path(folder))
        floors["socket"] = _floor.Pair("socket", 0, core, core, Path(folder))
        floors["shm"] = _floor.Pair("shm", 0, None, None, Path(folder))
        floors["zenoh"] = _floor.Pair("zenoh-tick", 0, core, core, Path(folder))
        by_hand = ByHand(core)
        assert by_hand.trial()[1] == one_process()[1]  # the same trial, bit for bit
        for pair in floors.values():
            pair.run(100, physics_tick())  # warm up

        def round_(into: dict[str, list[float]], names: list[str]) -> None:
            for name in names:
                if name == "a":
                    with Pinned(core):
                        t = physics_only()
                elif name == "b":
                    with Pinned(core):
                        t, metrics = one_process()
                    if "b0" in names:
                        with Pinned(core):
                            t0, before = one_process(PlanarBipedBefore)
                        assert metrics == before, (metrics, before)  # the same trial, bit for bit
                        into.setdefault("b0", []).append(t0)
                elif name == "c-hand":
                    t = by_hand.trial()[0]
                elif name in hosted:
                    t = hosted[name].trial()
                elif name in floors:
                    t = floors[name].run(TICKS, physics_tick())
                else:
                    continue
                into.setdefault(name, []).append(t)

        everything = ["a", "b", "b0", "c", "c-hand", "c-zenoh", "c-free", "c-mesh", "c-apart"]
        everything += ["pipe", "socket", "shm", "zenoh"]
        shuffle = np.random.default_rng(0).shuffle
        for _ in range(args.repeats):  # interleaved, so that all see the same machine load, in a shuffled order
            shuffle(everything)
            round_(runs, everything)
        during = _floor.machine_load()
        neighbour = _floor.Busy()
        try:
            besides = ["a", "b", "c", "c-hand", "c-zenoh", "socket", "zenoh", "shm"]
            for _ in range(args.busy_repeats):
                shuffle(besides)
                round_(busy, besides)
        finally:
            neighbour.close()
        beside = _floor.machine_load()
    finally:
        for pair in [*hosted.values(), *floors.values(), *filter(None, [by_hand])]:
            pair.close()
        session.close()
        shutil.rmtree(folder, ignore_errors=True)
    m = {name: median(v) for name, v in runs.items()}
    a, b, b0, c = m["a"], m["b"], m["b0"], m["c"]

    def ratio(x: str, y: str, of=runs) -> float:
        """The median over rounds of x / y in the same round (paired: a slow drift of the load cancels)."""
        return median(np.array(of[x]) / np.array(of[y]))

    print(
        f"one {SECONDS:g}-s trial ({TICKS} control ticks, {TICKS * 10} physics steps), {args.repeats} rounds, "
        "interleaved; "
        "times: medians; ratios: medians of the ratios within a round"
    )
    print(f"  (c) placed by lockstep.pin_cpus {args.pin}: {hosted['c'].where()}; during: {during}")
    print(f"  (a) physics only, open loop         {a * 1e3:7.1f} ms  ({SECONDS / a:5.1f}x real time)")
    print(f"  (b) controller + body, one process  {b * 1e3:7.1f} ms  ({SECONDS / b:5.1f}x real time)")
    print(f"  (b0) the same, the body as before batching  {b0 * 1e3:7.1f} ms  (identical metrics)")
    print(f"  (b0)/(b) = {ratio('b0', 'b'):.2f} (goal >= 1.6)   (b)/(a) = {ratio('b', 'a'):.2f} (goal <= 1.1)")
    print(f"  (c) controller + body over processes, socket link  {c * 1e3:7.1f} ms  ({SECONDS / c:5.1f}x real time)")
    print(f"  (c)/(b) = {ratio('c', 'b'):.2f} (goal <= 1.45)")
    print(
        "  (c-hand) (c) without the framework: the reflex controller in a process on the same core, a bare socket, "
        f"the messages by hand: (c-hand)/(b) = {ratio('c-hand', 'b'):.2f}; (c)/(c-hand) = {ratio('c', 'c-hand'):.2f} "
        "(goal <= 1.10)"
    )
    print(f"  (c-zenoh) placed as (c), ticks on a Zenoh lowlatency link: (c-zenoh)/(b) = {ratio('c-zenoh', 'b'):.2f}")
    print(
        f"  (c-free) not pinned, the body polling {args.spin_us:g} us, Zenoh link: (c-free)/(b) = "
        f"{ratio('c-free', 'b'):.2f}"
    )
    print(f"  (c-mesh) placed as (c), ticks on the mesh: (c-mesh)/(b) = {ratio('c-mesh', 'b'):.2f}")
    print(
        f"  (c-apart) a core each, the body polling {args.spin_us:g} us, Zenoh link: "
        f"(c-apart)/(b) = {ratio('c-apart', 'b'):.2f}"
    )
    print("  floors: the body steps (a)'s physics each tick, the controller answers at once; against (a):")
    where = f"core {core[0]}" if core else "not pinned"
    print(f"    pipe, both blocking, both on {where}: {ratio('pipe', 'a'):.2f}")
    print(f"    socket (SOCK_SEQPACKET), both blocking, both on {where}: {ratio('socket', 'a'):.2f}")
    print(f"    shared memory, both spinning, not pinned: {ratio('shm', 'a'):.2f}")
    print(f"    bare Zenoh, lockstep link, both blocking on {where}: {ratio('zenoh', 'a'):.2f}")
    print(
        "  framework / its bare transport in the same configuration: socket link ((c)/(b)) / (socket/(a)) "
        f"{ratio('c', 'b') / ratio('socket', 'a'):.2f}; Zenoh link ((c-zenoh)/(b)) / (bare Zenoh/(a)) "
        f"{ratio('c-zenoh', 'b') / ratio('zenoh', 'a'):.2f} (goal <= 1.10)"
    )
    print(f"beside one busy process, {args.busy_repeats} rounds ({beside}):")
    print(
        f"  (c)/(b) = {ratio('c', 'b', busy):.2f} (goal <= 1.6); (c-hand)/(b) = {ratio('c-hand', 'b', busy):.2f}; "
        f"(c-zenoh)/(b) = {ratio('c-zenoh', 'b', busy):.2f}"
    )
    print(f"    socket, both blocking on {where}: {ratio('socket', 'a', busy):.2f}")
    print(f"    shared memory, both spinning, not pinned: {ratio('shm', 'a', busy):.2f}")
    print(f"    bare Zenoh, lockstep link, both blocking on {where}: {ratio('zenoh', 'a', busy):.2f}")
    print(
        f"500 walking trials at (c): <= {500 * c * 10 / SECONDS:.0f} s (goal: E3.2 under 240 s; falls end trials early)"
    )
    if args.no_sweep:
        return
    n = args.grid**2
    print(f"sweep of {n} grid points (E3.1 subset), whole sfl run including start-up:", flush=True)
    for colocate, label in (
        (True, "controller inside each body worker (colocate: true)"),
        (False, "controller as its own process per worker"),
    ):
        lockstep = [f"lockstep.spin_us={args.spin_us}", f"lockstep.pin_cpus={args.pin}"]
        one = sweep(1, args.grid, colocate, lockstep)
        two = sweep(2, args.grid, colocate, lockstep)
        print(f"  {label}: 1 worker {one:.1f} s, 2 workers {two:.1f} s, speed-up {one / two:.2f}x (goal >= 1.7x)")
    print(f"after: {_floor.machine_load()}")


if __name__ == "__main__":
    main()
