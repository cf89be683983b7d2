"""Wall time of one 10-s trial of the planar walker, three ways, plus the parallel grid.

    python benchmarks/planar.py [--repeats 9] [--grid 15] [--pin never|auto|always]

(a) physics only, fixed open-loop command; (b) reflexive controller and body in one process;
(c) controller and body as two processes over Zenoh (lockstep, 1000 ticks), placed as ``sfl run``
    places them under ``pin_cpus`` ``--pin`` (default ``never``, as a scenario; the sweeps too);
then a sweep of a grid x grid subset of the E3.1 grid with 1 and with 2 body workers, with the
controllers colocated in the body workers and as separate processes.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import controller_spec, spawn_host, wait_alive  # noqa: E402

from bodies.planar_biped import PlanarBiped  # noqa: E402
from modules.controllers.reflex import ReflexController  # noqa: E402
from sfl_brain import bus  # noqa: E402
from sfl_brain.body import InProcessLink  # noqa: E402
from sfl_brain.host import BusLink  # noqa: E402
from sfl_brain.messages import TrialRequest  # noqa: E402
from sfl_brain.placement import assign, pin, usable_cpus  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
REQUEST = TrialRequest(
    trial_id=0,
    seed=0,
    body_params={"slope_deg": 0.0},
    controller_params={"alpha_hip": 10.0, "theta_hip_max_deg": 110.0},
    log=False,
)


def physics_only() -> float:
    body = PlanarBiped()
    body.logging = False
    body.start_trial(REQUEST)
    command = np.array([1.0, -1.0, 0.5, 0.5])
    t = time.perf_counter()
    for _ in range(1000):
        body.actuate(command)
    return time.perf_counter() - t


def one_process() -> float:
    body = PlanarBiped()
    body.link = InProcessLink(ReflexController())
    t = time.perf_counter()
    result = body.handle(REQUEST)
    assert result.metrics["time"] >= 9.99, result
    return time.perf_counter() - t


class Processes:
    """(c): the body here, the reflex controller hosted in its own process, lockstep over Zenoh."""

    def __init__(self, session, endpoint, cpus) -> None:
        run_id = "benchplanar"
        reference = "modules.controllers.reflex:ReflexController"
        self.proc = spawn_host(controller_spec(run_id, reference, endpoint, cpus))
        wait_alive(session, bus.alive_key(run_id, "controller"))
        self.body = PlanarBiped()
        self.body.link = BusLink(session, run_id, "body", "controller", 10.0)

    def trial(self) -> float:
        t = time.perf_counter()
        result = self.body.handle(REQUEST)
        elapsed = time.perf_counter() - t
        assert result.metrics["time"] >= 9.99, result
        return elapsed

    def close(self) -> None:
        self.body.link.close()
        self.proc.terminate()
        self.proc.wait(timeout=10)


def sweep(workers: int, grid: int, colocate: bool, pin_cpus: str) -> float:
    from sfl_brain.run import run
    from sfl_brain.scenario import load

    plan = load(
        ROOT / "scenarios" / "e3_1_viability.yaml",
        [
            f"modules.body.workers={workers}",
            f"space.0.steps={grid}",
            f"space.1.steps={grid}",
            "record.body_every=0",
            f"modules.controller.colocate={str(colocate).lower()}",
            f"pin_cpus={pin_cpus}",
        ],
    )
    with tempfile.TemporaryDirectory() as tmp:
        t = time.perf_counter()
        _, summary = run(plan, Path(tmp) / "run")
        assert summary["status"] == "completed", summary
        return time.perf_counter() - t


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeats", type=int, default=9)
    parser.add_argument("--grid", type=int, default=15)
    parser.add_argument("--pin", choices=["never", "auto", "always"], default="never", help="pin_cpus")
    args = parser.parse_args()
    endpoint = bus.free_endpoint()
    session = bus.open_session([endpoint], [])
    cpus = usable_cpus()
    # as sfl run places one body worker (this process) and its controller process
    placed = assign(["body", "controller"], cpus, args.pin)
    pin(placed.get("body"))
    a, b, c = [], [], []
    try:
        over_zenoh = Processes(session, endpoint, placed.get("controller"))
        over_zenoh.trial()  # warm up
        for _ in range(args.repeats):  # interleaved, so that all three see the same machine load
            a.append(physics_only())
            b.append(one_process())
            c.append(over_zenoh.trial())
        over_zenoh.close()
    finally:
        pin(cpus)  # sfl run places the sweeps' processes itself
        session.close()
    a, b, c = np.median(a), np.median(b), np.median(c)
    where = f"pin {args.pin}: " + (
        f"body on cores {placed['body']}, controller on {placed['controller']}" if placed else "not pinned"
    )
    print(f"one 10-s trial (1000 control ticks, 10 000 physics steps), median of {args.repeats}, interleaved, {where}:")
    print(f"  (a) physics only, open loop         {a * 1e3:7.1f} ms  ({10 / a:5.1f}x real time)")
    print(f"  (b) controller + body, one process  {b * 1e3:7.1f} ms  ({10 / b:5.1f}x real time)")
    print(f"  (c) controller + body over Zenoh    {c * 1e3:7.1f} ms  ({10 / c:5.1f}x real time; goal >= 20x)")
    print(f"  (c)/(b) = {c / b:.2f} (goal <= 1.5)   (b)/(a) = {b / a:.2f}")
    print(f"  500 walking trials at (c): <= {500 * c:.0f} s (goal: E3.2 under 240 s; falls end trials early)")
    n = args.grid**2
    print(f"sweep of {n} grid points (E3.1 subset), whole sfl run including start-up:")
    for colocate, label in (
        (True, "controller inside each body worker (colocate: true)"),
        (False, "controller as its own process per worker"),
    ):
        one = sweep(1, args.grid, colocate, args.pin)
        two = sweep(2, args.grid, colocate, args.pin)
        print(f"  {label}: 1 worker {one:.1f} s, 2 workers {two:.1f} s, speed-up {one / two:.2f}x (goal >= 1.7x)")


if __name__ == "__main__":
    main()
