"""The humanoid on PyBullet against the humanoid on MuJoCo (issue 31): one 10-s trial in one process, side by side.

    python benchmarks/engines.py [--repeats 9] [--quick]

Each item is one trial of 10 s of simulated time (1000 control ticks of 10 ms, 4000 physics steps at 400 Hz) of the
same body (bodies/humanoid.py, ``physics: pybullet`` or ``mujoco``), interleaved in a shuffled order so that all see
the same machine load, ``--repeats`` rounds. Times are medians over the rounds, of wall time and of this process's CPU
time; ratios PyBullet / MuJoCo are medians of the ratios within each round (paired: a slow drift of the load cancels);
the load average is printed before, during and after:

(a)  physics only: the body's ``actuate`` with the standing command 1000 times on a freshly started trial (the servo
     law every physics step, the energy sum, judging; no sensing, no controller), as benchmarks/humanoid.py (a);
(a-walk) physics only while walking: (a) with the gait's own commands, the 1000 commands the CPG (b) sent in one
     trial on that engine, replayed in order, open loop (no sensing, no controller). Walking contacts cost an
     engine differently from standing ones, so this, not (a), is the physics a walking trial pays;
(a') the body's whole trial with a constant controller (the standing pose): (a) plus sensing (joints, IMU, the eight
     foot pressure sensors from the contacts) and the framework's tick;
(b)  the default gait: ``CPGController`` with the ``humanoid_nao`` circuit in the body's process (``InProcessLink``):
     the trial as ``sfl run`` runs it with ``colocate: true``. The CPG is the same on both engines: its share caps the
     ratio of (b);
(b-numba) (b) with the CPG's RK4 and layers compiled (``CPGParams.kernel: numba``, the ``fast`` extra) on both
     engines, when numba is installed: the CPG's share made small, what is left is each engine's body.

Goal (issue 31): a one-process MuJoCo humanoid trial >= 3x the PyBullet trial's speed. The gait does not reach the 1.5-m
line in 10 s on either engine (13-14 s), so every timed trial lasts the full 10 s; a fall fails the benchmark.
``--quick``: 1 round, for a smoke test.
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _floor import machine_load  # noqa: E402
from humanoid import REQUEST, STANDING_COMMAND, Standing, gait_commands, replayed  # noqa: E402

from sfl_brain.bodies.humanoid import Humanoid  # noqa: E402
from sfl_brain.body import InProcessLink  # noqa: E402
from sfl_brain.modules.controllers.cpg import CPGController, CPGParams  # noqa: E402

SECONDS = 10.0  # simulated time of a trial: the gait reaches the 1.5-m line at about 13.6 s, so every trial lasts it

ENGINES = ("pybullet", "mujoco")
ITEMS = {
    "a": "physics only, standing command",
    "a-walk": "physics only, the gait's commands",
    "a1": "body trial, constant controller",
    "b": "CPG + body",
}
NUMBA = importlib.util.find_spec("numba") is not None
if NUMBA:
    ITEMS["b-numba"] = "CPG (compiled kernel) + body"


def new_body(physics: str, controller=None) -> Humanoid:
    body = Humanoid(Humanoid.Params(duration=SECONDS, physics=physics))
    body.logging = False
    if controller is not None:
        body.link = InProcessLink(controller)
    return body


def physics_only(body: Humanoid) -> tuple[float, float]:
    """(a): wall and CPU seconds of 1000 ticks of ``actuate`` with the standing command."""
    body.start_trial(REQUEST)
    wall, cpu = time.perf_counter(), time.process_time()
    for _ in range(int(round(SECONDS / body.params.control_dt))):
        body.actuate(STANDING_COMMAND)
    return time.perf_counter() - wall, time.process_time() - cpu


def whole_trial(body: Humanoid) -> tuple[float, float]:
    """(a') or (b): wall and CPU seconds of the body's trial with its link's controller; it must last the full 10 s."""
    wall, cpu = time.perf_counter(), time.process_time()
    result = body.handle(REQUEST)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    assert result.metrics["time"] >= SECONDS - 1e-6 and not result.metrics["fell"], result
    return wall, cpu


def main(argv: list[str] | None = None) -> dict[str, float]:
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeats", type=int, default=9, help="rounds")
    parser.add_argument("--quick", action="store_true", help="1 round: a smoke test")
    args = parser.parse_args(argv)
    repeats = 1 if args.quick else args.repeats
    print(f"before: {machine_load()}", flush=True)
    bodies, commands = {}, {}
    for engine in ENGINES:
        recorder = new_body(engine, CPGController(CPGParams(circuit="humanoid_nao")))
        commands[engine] = gait_commands(recorder)
        bodies["a", engine] = new_body(engine)
        bodies["a-walk", engine] = new_body(engine)
        bodies["a1", engine] = new_body(engine, Standing())
        bodies["b", engine] = new_body(engine, CPGController(CPGParams(circuit="humanoid_nao")))
        if NUMBA:
            compiled = CPGController(CPGParams(circuit="humanoid_nao", kernel="numba"))
            bodies["b-numba", engine] = new_body(engine, compiled)
    wall: dict[tuple, list[float]] = {key: [] for key in bodies}
    cpu: dict[tuple, list[float]] = {key: [] for key in bodies}

    def timed(key: tuple) -> tuple[float, float]:
        item, engine = key
        if item == "a":
            return physics_only(bodies[key])
        if item == "a-walk":
            return replayed(bodies[key], commands[engine])
        return whole_trial(bodies[key])

    try:
        for key in bodies:  # warm-up: worlds built, caches filled
            timed(key)
        order, shuffle = list(bodies), np.random.default_rng(0).shuffle
        for _ in range(repeats):  # interleaved in a shuffled order, so that all see the same machine load
            shuffle(order)
            for key in order:
                w, c = timed(key)
                wall[key].append(w)
                cpu[key].append(c)
        during = machine_load()
    finally:
        for body in bodies.values():
            body.close()

    def ratio(times: dict, item: str) -> float:
        """PyBullet / MuJoCo: the median over rounds of the ratio within a round."""
        return float(np.median(np.array(times[item, "pybullet"]) / np.array(times[item, "mujoco"])))

    print(
        f"engines: one {SECONDS:g}-s humanoid trial (1000 control ticks, 4000 physics steps) in one process, {repeats} "
        "rounds, interleaved; times: medians (wall, and CPU of this process); ratios: PyBullet / MuJoCo, medians of "
        "the ratios within a round"
    )
    print(f"  during: {during}")
    out = {}
    for item, label in ITEMS.items():
        pb, mj = (float(np.median(wall[item, engine])) for engine in ENGINES)
        pb_cpu, mj_cpu = (float(np.median(cpu[item, engine])) for engine in ENGINES)
        goal = "; goal >= 3x" if item.startswith("b") else ""
        name = "(a')" if item == "a1" else f"({item})"
        print(
            f"  {name:9s} {label:34s} PyBullet {pb * 1e3:7.1f} ms ({SECONDS / pb:5.1f}x real time), "
            f"MuJoCo {mj * 1e3:7.1f} ms ({SECONDS / mj:5.1f}x); wall {ratio(wall, item):.2f}x, CPU "
            f"{ratio(cpu, item):.2f}x ({pb_cpu * 1e3:.0f} / {mj_cpu * 1e3:.0f} ms){goal}"
        )
        out[item] = ratio(wall, item)
    walking = {engine: float(np.median(cpu["a-walk", engine])) for engine in ENGINES}
    print(
        f"  what bounds the goal: the walking physics alone, (a-walk), is {out['a-walk']:.2f}x on wall time; a trial "
        f"costs that plus what both engines pay alike (the CPG, sensing, the tick): (b) - (a-walk) = "
        + ", ".join(f"{e} {(float(np.median(cpu['b', e])) - walking[e]) * 1e3:.0f} ms CPU" for e in ENGINES)
    )
    print(f"after: {machine_load()}")
    return out


if __name__ == "__main__":
    main()
