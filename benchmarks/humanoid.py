"""Wall and CPU time of one trial of the NAO-sized humanoid walking on its CPG, in one process and over processes.

    python benchmarks/humanoid.py [--seconds 16] [--repeats 9] [--spin-us 400] [--pin auto|always|never] [--quick]

Each item is one trial of ``--seconds`` of simulated time (default 16 s, the mean length of chapter 5's learning
trials, issue 31: 1600 control ticks of 10 ms, 6400 PyBullet steps at 400 Hz; the finish line is moved out of reach so
that every trial lasts that long), interleaved in a shuffled order so that all see the same machine load,
``--repeats`` rounds; times are medians over the rounds, ratios medians of the ratios within each round. Beside each
wall time, the CPU time the trial used (this process's for (a)-(b), the two hosting processes' for (c)) and the CPU
real-time factor (simulated s per CPU s); the load average before, during and after is printed:

(a) physics only: the body built for the trial, then ``actuate`` with the standing command once a tick (no sensing, no
    controller, no messages), as ``benchmarks/planar.py`` (a) steps the planar biped;
(a-walk) physics only while walking: (a) with the commands the CPG of (b) sent in one trial, replayed in order, open
    loop (benchmarks/engines.py (a-walk)): walking contacts cost PyBullet less than standing ones, so this, not (a),
    is the physics a walking trial pays, the floor under (b) and (b-numba);
(a') the body's whole trial with a constant controller in its process (the standing pose): (a) plus sensing (the
    foot pressure sensors read PyBullet's contact points), judging and the framework's tick (messages, checks);
(b) the default gait: ``CPGController`` with the ``humanoid_nao`` circuit in the body's process (``InProcessLink``),
    the trial as ``sfl run`` runs it with ``colocate: true``; (a), (a') and (b) run on the core (c) places its pair on,
    so that all meet the same neighbours on a busy machine;
(b-numba) (b) with the network's RK4 and layers compiled (``CPGParams.kernel: numba``, the ``fast`` extra; issue 31),
    when numba is installed; its commands are within 1e-9 of numpy's per tick, so its walk is not bit for bit (b)'s;
(c) the same trial with controller and body each hosted in its own process by ``runtime.host``, as ``sfl run`` hosts
    them: placed as ``lockstep.pin_cpus`` ``--pin`` says (default ``auto``: both on one core, blocking), their frames
    and commands on their socket link (``lockstep.link: socket``); the trial is a request from this process,
    timed from request to reply;
(c-zenoh) placed as (c), the ticks on a Zenoh lowlatency session (``lockstep.link: zenoh``): what the socket gives;
(c-free) not pinned, the body polling up to ``--spin-us`` (``lockstep.spin_us``, default the scenario's 400 us) for
    each command, on the Zenoh link: what the placement alone gives;
(c-mesh) placed as (c), but the ticks on the run's mesh: what the link alone gives;
(c-before) not pinned, polling, on the mesh: as before issue 24.
Every trial over processes is checked bit for bit against the one-process trial once.

Goals (issue 24): (c) >= 20x real time and (b)/(c) >= 0.8 (issue 16: (b) >= 20x, and the CPG plus the bus cheaper than
the physics: (c) - (a) < (a)); issue 31: over processes / one process <= 1.2 in CPU time. A trial that ends early (a
fall) fails the benchmark. ``--quick``: 2 repeats, (c) only, for a smoke test.
"""

from __future__ import annotations

import argparse
import importlib.util
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import HostedPair, Pinned  # noqa: E402
from _floor import machine_load  # noqa: E402

from sfl_brain.bodies.humanoid import JOINT_NAMES, Humanoid  # noqa: E402
from sfl_brain.bodies.humanoid_table import STANDING  # noqa: E402
from sfl_brain.body import Controller, InProcessLink  # noqa: E402
from sfl_brain.messages import TrialRequest  # noqa: E402
from sfl_brain.modules.controllers.cpg import CPGController, CPGParams  # noqa: E402
from sfl_brain.runtime import bus  # noqa: E402
from sfl_brain.runtime.host import request  # noqa: E402
from sfl_brain.runtime.liveness import cpu_sample  # noqa: E402
from sfl_brain.scenario import load  # noqa: E402

#: the body's poll for each command in the humanoid's scenario (us), the benchmark's default
SCENARIO = Path(__file__).resolve().parents[1] / "scenarios" / "humanoid_walk.yaml"
SCENARIO_SPIN_US = load(SCENARIO).scenario.lockstep.spin_us

SECONDS = 16.0  # simulated time of a trial (--seconds): chapter 5's learning trials last 16 s on average (issue 31)
BODY_PARAMS = {"duration": SECONDS, "finish_line": 1000.0}  # out of reach: every trial lasts SECONDS
CONTROLLER_PARAMS = {"circuit": "humanoid_nao"}
REQUEST = TrialRequest(trial_id=0, seed=0, body_params={}, controller_params={}, log=False)
STANDING_COMMAND = np.array([STANDING[name] for name in JOINT_NAMES])


class Standing(Controller):
    """Every joint held at the standing pose: the constant controller of (a')."""

    WRITES = tuple(f"q_{name}" for name in JOINT_NAMES)

    def configure(self, params: dict, seed: int) -> None:
        pass

    def step(self, sensors: np.ndarray) -> np.ndarray:
        return STANDING_COMMAND


def cpu_seconds(pids: list[int]) -> float:
    """The CPU seconds the processes ``pids`` have used so far (``liveness.cpu_sample``: their threads' scheduler
    statistics on Linux)."""
    samples = [cpu_sample(pid) for pid in pids]
    assert all(samples), f"a hosting process of {pids} is gone"
    return sum(sample.cpu for sample in samples)


def new_body() -> Humanoid:
    body = Humanoid(Humanoid.Params(**BODY_PARAMS))
    body.logging = False
    return body


def physics_only(body: Humanoid) -> float:
    """(a): a trial's ticks of ``actuate`` with the standing command on a freshly started trial."""
    body.start_trial(REQUEST)
    t = time.perf_counter()
    for _ in range(int(round(SECONDS / body.params.control_dt))):
        body.actuate(STANDING_COMMAND)
    return time.perf_counter() - t


def gait_commands(body: Humanoid) -> list[np.ndarray]:
    """The commands the controller on ``body``'s link sends in one whole trial, in order (for (a-walk)); closes
    ``body``."""
    sent, actuate = [], body.actuate

    def keep(command: np.ndarray) -> None:
        sent.append(np.array(command, dtype=float))
        actuate(command)

    body.actuate = keep
    try:
        result = body.handle(REQUEST)
        ticks = int(round(body.params.duration / body.params.control_dt))
    finally:
        body.close()
    assert len(sent) == ticks and not result.metrics["fell"], f"the gait ran {len(sent)} of {ticks} ticks: {result}"
    return sent


def _blew_up(body: Humanoid) -> int:
    """How often MuJoCo found the simulation unstable and reset it (0 on PyBullet, which has no such count)."""
    if body.params.physics != "mujoco":
        return 0
    import mujoco

    return int(body.world.data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number)


def replayed(body: Humanoid, commands: list[np.ndarray]) -> tuple[float, float]:
    """(a-walk): wall and CPU seconds of ``actuate`` with ``commands`` in order, on a freshly started trial; the
    replayed gait must not fall (it walks open loop from the same start)."""
    body.start_trial(REQUEST)
    blew_up = _blew_up(body)
    wall, cpu = time.perf_counter(), time.process_time()
    down = 0
    for command in commands:
        body.actuate(command)
        down += body.fell or body.left_lane  # one add a tick: the judging already ran in actuate
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    assert not down, f"the replayed gait fell or left its lane on {down} ticks: (a-walk) would not time a walk"
    assert _blew_up(body) == blew_up, "the physics blew up during the replay: (a-walk) would not time a walk"
    return wall, cpu


def whole_trial(body: Humanoid) -> tuple[float, dict]:
    """(a') or (b): the body's trial with the controller of its link; the trial must last the full SECONDS."""
    t = time.perf_counter()
    result = body.handle(REQUEST)
    elapsed = time.perf_counter() - t
    assert result.metrics["time"] >= SECONDS - 1e-6 and not result.metrics["fell"], result
    return elapsed, {"success": result.success, **result.metrics}


class Processes(HostedPair):
    """(c): the humanoid and the CPG controller, each hosted in its own process as ``sfl run`` hosts them; a trial is a
    request from here, as the supervisor sends it."""

    def __init__(self, session, endpoint: str, run_id: str, folder: str, **placed) -> None:
        super().__init__(
            session,
            endpoint,
            run_id,
            "sfl_brain.modules.controllers.cpg:CPGController",
            "sfl_brain.bodies.humanoid:Humanoid",
            folder=folder,
            controller_params=CONTROLLER_PARAMS,
            body_params=BODY_PARAMS,
            **placed,
        )
        self.session, self.key = session, bus.key(run_id, "body", TrialRequest.TAG)

    def trial(self) -> tuple[float, dict]:
        t = time.perf_counter()
        result = request(self.session, self.key, REQUEST, 120.0)
        elapsed = time.perf_counter() - t
        assert result.metrics["time"] >= SECONDS - 1e-6 and not result.metrics["fell"], result
        return elapsed, {"success": result.success, **result.metrics}


def main(argv: list[str] | None = None) -> dict[str, float]:
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeats", type=int, default=9, help="rounds")
    parser.add_argument(
        "--spin-us", type=float, default=SCENARIO_SPIN_US, help="lockstep.spin_us (default: the humanoid scenario's)"
    )
    parser.add_argument("--pin", choices=["auto", "always", "never"], default="auto", help="lockstep.pin_cpus of (c)")
    parser.add_argument("--quick", action="store_true", help="2 repeats, (c) only: a smoke test")
    parser.add_argument("--seconds", type=float, default=SECONDS, help="simulated s of a trial (default 16)")
    args = parser.parse_args(argv)
    if not args.seconds > 0:
        parser.error(f"--seconds: expected a time > 0; got {args.seconds}")
    set_seconds(args.seconds)
    repeats = 2 if args.quick else args.repeats
    spin = args.spin_us * 1e-6
    print(f"before: {machine_load()}", flush=True)
    endpoint = bus.free_endpoint()
    session = bus.open_session([endpoint], [])
    folder = tempfile.mkdtemp(prefix="sfl-")
    physics_body = new_body()
    walking_body = new_body()
    recorder = new_body()
    recorder.link = InProcessLink(CPGController(CPGParams(**CONTROLLER_PARAMS)))
    commands = gait_commands(recorder)
    standing_body = new_body()
    standing_body.link = InProcessLink(Standing())
    cpg_body = new_body()
    cpg_body.link = InProcessLink(CPGController(CPGParams(**CONTROLLER_PARAMS)))
    numba_body = None
    if importlib.util.find_spec("numba") is not None:
        numba_body = new_body()
        numba_body.link = InProcessLink(CPGController(CPGParams(**CONTROLLER_PARAMS, kernel="numba")))
    times: dict[str, list[float]] = {}
    cpu: dict[str, list[float]] = {}
    pairs: dict[str, Processes] = {}
    variants = {
        "c": {"pin": args.pin, "link": "socket", "spin": spin},
        "c-zenoh": {"pin": args.pin, "link": "zenoh", "spin": spin},
        "c-free": {"pin": "never", "link": "zenoh", "spin": spin},
        "c-mesh": {"pin": args.pin, "link": "mesh", "spin": spin},
        "c-before": {"pin": "never", "link": "mesh", "spin": spin},
    }
    if args.quick:
        variants = {"c": variants["c"]}
    try:
        for name, placed in variants.items():
            pairs[name] = Processes(session, endpoint, f"benchhumanoid{len(pairs)}", folder, **placed)
        in_process = whole_trial(cpg_body)[1]  # warm-up: worlds built, caches filled
        for pair in pairs.values():
            over_bus = pair.trial()[1]
            assert over_bus == in_process, (over_bus, in_process)  # the same trial over processes, bit for bit
        whole_trial(standing_body)
        if numba_body is not None:
            whole_trial(numba_body)  # numba compiles or loads its cache
        core = pairs["c"].placement.of("body")  # the one-process trials run on the pair's core
        order, shuffle = ["a", "a-walk", "a1", "b", *pairs], np.random.default_rng(0).shuffle
        if numba_body is not None:
            order.append("b-numba")
        for _ in range(repeats):  # interleaved in a shuffled order, so that all see the same machine load
            shuffle(order)
            for name in order:
                if name in pairs:
                    pids = [proc.pid for proc in pairs[name].procs]
                    used = cpu_seconds(pids)
                    t = pairs[name].trial()[0]
                    used = cpu_seconds(pids) - used
                else:
                    with Pinned(core):
                        used = time.process_time()
                        if name == "a":
                            t = physics_only(physics_body)
                        elif name == "a-walk":
                            t = replayed(walking_body, commands)[0]
                        else:
                            body = {"a1": standing_body, "b": cpg_body, "b-numba": numba_body}[name]
                            t = whole_trial(body)[0]
                        used = time.process_time() - used
                times.setdefault(name, []).append(t)
                cpu.setdefault(name, []).append(used)
        during = machine_load()
    finally:
        for pair in pairs.values():
            pair.close()
        session.close()
        shutil.rmtree(folder, ignore_errors=True)
        for body in (physics_body, walking_body, standing_body, cpg_body, numba_body):
            if body is not None:
                body.close()
    m = {name: float(np.median(v)) for name, v in times.items()}
    mc = {name: float(np.median(v)) for name, v in cpu.items()}
    a, a1, b, c = m["a"], m["a1"], m["b"], m["c"]
    ticks = int(round(SECONDS / physics_body.params.control_dt))
    steps = ticks * physics_body.params.substeps

    def rt(name: str) -> str:
        """Wall time, wall and CPU real-time factors of a variant."""
        return (f"{m[name] * 1e3:7.1f} ms  ({SECONDS / m[name]:5.1f}x real time; CPU {mc[name] * 1e3:7.1f} ms, "
                f"{SECONDS / mc[name]:5.1f}x)")

    def ratio(x: str, y: str) -> float:
        """The median over rounds of x / y in the same round (paired: a slow drift of the load cancels)."""
        return float(np.median(np.array(times[x]) / np.array(times[y])))

    def cpu_ratio(x: str, y: str) -> float:
        """``ratio`` of the CPU seconds."""
        return float(np.median(np.array(cpu[x]) / np.array(cpu[y])))

    print(
        f"humanoid: one {SECONDS:g}-s trial ({ticks} control ticks, {steps} physics steps), {repeats} rounds, "
        "interleaved; times: medians; ratios: medians of the ratios within a round; CPU: the trial's processes"
    )
    print(f"  (c) placed by lockstep.pin_cpus {args.pin}: {pairs_where(args.pin)}; during: {during}")
    print(f"  (a)  physics only, standing command      {rt('a')}")
    print(f"  (a-walk) physics only, the gait's commands {rt('a-walk')}")
    print(f"  (a') body trial, constant controller     {rt('a1')}")
    print(f"  (b)  CPG + body, one process             {rt('b')}  goal >= 20x real time")
    if "b-numba" in m:
        print(
            f"  (b-numba) (b), compiled CPG kernel      {rt('b-numba')}; (b)/(b-numba) = {ratio('b', 'b-numba'):.2f}x "
            "the one-process speed (issue 31's goal >= 1.4)"
        )
    floor = m["a-walk"] + a1 - a  # walking physics, sensing and the tick: what no controller can take away
    print(
        f"  the floor under a one-process trial: walking physics + sensing and tick (a-walk) + (a') - (a) = "
        f"{floor * 1e3:.1f} ms; (b) / floor = {b / floor:.2f}x, the most any controller could gain (issue 31: 1.4)"
    )
    print(f"  (c)  CPG + body over processes           {rt('c')}  goal >= 20x real time")
    print(f"  (b)/(c) = {ratio('b', 'c'):.2f} of the one-process speed over processes (goal >= 0.8)")
    print(
        f"  CPU over processes / one process: (c)/(b) = {cpu_ratio('c', 'b'):.2f} (issue 31's goal <= 1.2)"
    )
    print(f"  (b)/(a) = {ratio('b', 'a'):.2f}   (c)/(b) = {ratio('c', 'b'):.2f}   (c)/(a) = {ratio('c', 'a'):.2f}")
    for name, label in (
        ("c-zenoh", "placed as (c), ticks on a Zenoh lowlatency link (lockstep.link: zenoh)"),
        ("c-free", f"not pinned, the body polling {args.spin_us:g} us, Zenoh link"),
        ("c-mesh", "placed as (c), ticks on the mesh"),
        ("c-before", f"not pinned, the body polling {args.spin_us:g} us, ticks on the mesh (before issue 24)"),
    ):
        if name in m:
            print(f"  ({name}) {label}: {m[name] * 1e3:.1f} ms, ({name})/(b) = {ratio(name, 'b'):.2f}")
    print(
        f"  beyond the physics: sensing + framework (a')-(a) = {(a1 - a) * 1e3:.1f} ms, CPG (b)-(a') = "
        f"{(b - a1) * 1e3:.1f} ms, bus (c)-(b) = {(c - b) * 1e3:.1f} ms; CPG + bus (c)-(a) = {(c - a) * 1e3:.1f} ms "
        f"vs physics {a * 1e3:.1f} ms (goal: less)"
    )
    print(f"after: {machine_load()}")
    return {"physics": a, "standing_trial": a1, "one_process": b, "processes": c, "cpu_one_process": mc["b"],
            "cpu_processes": mc["c"]}


def set_seconds(seconds: float) -> None:
    """Every trial of this run lasts ``seconds`` of simulated time."""
    global SECONDS, BODY_PARAMS
    SECONDS = float(seconds)
    BODY_PARAMS = {"duration": SECONDS, "finish_line": 1000.0}


def pairs_where(mode: str) -> str:
    from sfl_brain.runtime.placement import Pair, place, usable_cpus

    return place([Pair("body", "controller")], [], usable_cpus(), mode).reason


if __name__ == "__main__":
    main()
