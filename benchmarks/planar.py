"""Wall time of one 10-s trial of the planar walker, three ways, plus the parallel grid.

    python benchmarks/planar.py [--repeats 9] [--grid 15] [--spin-us 200] [--pin never|auto|always]

(a) physics only, fixed open-loop command; (b) reflexive controller and body in one process;
(b0) the same with the body as it stepped before its hot path was batched (``_planar_before.py``),
    with the same metrics bit for bit (checked on every repeat);
(c) controller and body each hosted in its own process by ``sfl_brain.host``, as ``sfl run`` hosts
    them, lockstep over Zenoh (1000 ticks); the trial is a request from this process, timed from
    request to reply. The body waits for each command as ``lockstep.spin_us`` ``--spin-us`` says
    and the two are placed as ``lockstep.pin_cpus`` ``--pin`` says (defaults as in a scenario; the
    sweeps too); (c0) is the same pair with the body sleeping at once (spin 0), for comparison;
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
from _planar_before import PlanarBipedBefore  # noqa: E402

from sfl_brain import bus  # noqa: E402
from sfl_brain.bodies.planar_biped import PlanarBiped  # noqa: E402
from sfl_brain.body import InProcessLink  # noqa: E402
from sfl_brain.host import request  # noqa: E402
from sfl_brain.messages import SensorFrame, TrialRequest  # noqa: E402
from sfl_brain.modules.controllers.reflex import ReflexController  # noqa: E402
from sfl_brain.placement import assign, usable_cpus  # noqa: E402

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


def one_process(body_class=PlanarBiped) -> tuple[float, dict]:
    body = body_class()
    body.link = InProcessLink(ReflexController())
    t = time.perf_counter()
    result = body.handle(REQUEST)
    elapsed = time.perf_counter() - t
    assert result.metrics["time"] >= 9.99, result
    return elapsed, {"success": result.success, "quality": result.quality, **result.metrics}


class Processes:
    """(c): the walker and the reflex controller, each hosted in its own process as sfl run hosts
    them; a trial is a request from here, as the supervisor sends it."""

    def __init__(self, session, endpoint, run_id, placed, spin) -> None:
        controller = controller_spec(run_id, "sfl_brain.modules.controllers.reflex:ReflexController", endpoint)
        body = controller_spec(run_id, "sfl_brain.bodies.planar_biped:PlanarBiped", endpoint, placed.get("body"))
        body.update(instance="body", spec_name="body", routes={SensorFrame.TAG: "controller"}, spin=spin)
        controller["cpus"] = placed.get("controller")
        self.procs = [spawn_host(controller), spawn_host(body)]
        for name in ("controller", "body"):
            wait_alive(session, bus.alive_key(run_id, name))
        self.session, self.key = session, bus.key(run_id, "body", TrialRequest.TAG)

    def trial(self) -> float:
        t = time.perf_counter()
        result = request(self.session, self.key, REQUEST, 60.0)
        elapsed = time.perf_counter() - t
        assert result.metrics["time"] >= 9.99, result
        return elapsed

    def close(self) -> None:
        for proc in self.procs:
            proc.terminate()
            proc.wait(timeout=10)


def sweep(workers: int, grid: int, colocate: bool, lockstep: list[str]) -> float:
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
            *lockstep,
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
    parser.add_argument("--spin-us", type=float, default=200.0, help="lockstep.spin_us")
    parser.add_argument("--pin", choices=["never", "auto", "always"], default="never", help="lockstep.pin_cpus")
    args = parser.parse_args()
    endpoint = bus.free_endpoint()
    session = bus.open_session([endpoint], [])
    # as sfl run places one body worker and its controller process
    placed = assign(["body", "controller"], usable_cpus(), args.pin)
    a, b, b0, c, c0 = [], [], [], [], []
    pairs = []
    try:
        pairs.append(Processes(session, endpoint, "benchplanar", placed, args.spin_us * 1e-6))
        pairs.append(Processes(session, endpoint, "benchplanar0", placed, 0.0))
        for pair in pairs:
            pair.trial()  # warm up
        for _ in range(args.repeats):  # interleaved, so that all see the same machine load
            a.append(physics_only())
            elapsed, metrics = one_process()
            b.append(elapsed)
            elapsed, before = one_process(PlanarBipedBefore)
            b0.append(elapsed)
            assert metrics == before, (metrics, before)  # the same trial, bit for bit
            c.append(pairs[0].trial())
            c0.append(pairs[1].trial())
    finally:
        for pair in pairs:
            pair.close()
        session.close()
    a, b, b0, c, c0 = np.median(a), np.median(b), np.median(b0), np.median(c), np.median(c0)
    where = f"spin {args.spin_us:g} us, pin {args.pin}: " + (
        f"body on cores {placed['body']}, controller on {placed['controller']}" if placed else "not pinned"
    )
    print(f"one 10-s trial (1000 control ticks, 10 000 physics steps), median of {args.repeats}, interleaved, {where}:")
    print(f"  (a) physics only, open loop         {a * 1e3:7.1f} ms  ({10 / a:5.1f}x real time)")
    print(f"  (b) controller + body, one process  {b * 1e3:7.1f} ms  ({10 / b:5.1f}x real time)")
    print(f"  (c) controller + body over Zenoh    {c * 1e3:7.1f} ms  ({10 / c:5.1f}x real time; goal >= 20x)")
    print(f"  (b0) the same, the body as before batching  {b0 * 1e3:7.1f} ms  (identical metrics)")
    print(f"  (b0)/(b) = {b0 / b:.2f} (goal >= 1.6)   (b)/(a) = {b / a:.2f} (goal <= 1.1)")
    print(f"  (c)/(b) = {c / b:.2f} (goal <= 1.35)")
    print(f"  (c0) the same, the body sleeping at once  {c0 * 1e3:7.1f} ms, (c0)/(b) = {c0 / b:.2f}")
    print(f"  500 walking trials at (c): <= {500 * c:.0f} s (goal: E3.2 under 240 s; falls end trials early)")
    n = args.grid**2
    print(f"sweep of {n} grid points (E3.1 subset), whole sfl run including start-up:")
    for colocate, label in (
        (True, "controller inside each body worker (colocate: true)"),
        (False, "controller as its own process per worker"),
    ):
        lockstep = [f"lockstep.spin_us={args.spin_us}", f"lockstep.pin_cpus={args.pin}"]
        one = sweep(1, args.grid, colocate, lockstep)
        two = sweep(2, args.grid, colocate, lockstep)
        print(f"  {label}: 1 worker {one:.1f} s, 2 workers {two:.1f} s, speed-up {one / two:.2f}x (goal >= 1.7x)")


if __name__ == "__main__":
    main()
