"""Wall time of one 10-s trial of the NAO-sized humanoid walking on its CPG, three ways, side by side.

    python benchmarks/humanoid.py [--repeats 5] [--spin-us 400] [--pin never|auto|always] [--quick]

Each item is one trial of 10 s of simulated time (1000 control ticks of 10 ms, 4000 PyBullet steps at 400 Hz),
interleaved so that all see the same machine load; medians over ``--repeats``:

(a) physics only: the body built for the trial, then ``actuate`` with the standing command 1000 times (no sensing, no
    controller, no messages), as ``benchmarks/planar.py`` (a) steps the planar biped;
(a') the body's whole trial with a constant controller in its process (the standing pose): (a) plus sensing (the
    foot pressure sensors read PyBullet's contact points), judging and the framework's tick (messages, checks);
(b) the default gait: ``CPGController`` with the ``humanoid_nao`` circuit in the body's process (``InProcessLink``),
    the trial as ``sfl run`` runs it with ``colocate: true``;
(c) the same trial with controller and body each hosted in its own process by ``sfl_brain.host``, as ``sfl run`` hosts
    them, lockstep over Zenoh (1000 ticks); the trial is a request from this process, timed from request to reply.
    The body waits for each command as ``lockstep.spin_us`` ``--spin-us`` says, the two are placed as
    ``lockstep.pin_cpus`` ``--pin`` says (defaults as in ``scenarios/humanoid_walk.yaml``: spin 400 us, not pinned).

Goals (issue 16): (b) >= 20x real time, (c) >= 10x, and the CPG plus the bus cheaper than the physics:
(c) - (a) < (a). The gait does not reach the 1.5-m line in 10 s (about 13.2 s, docs/results/chapter4/humanoid.md),
so every timed trial lasts the full 10 s; a trial that ends early (a fall) fails the benchmark.
``--quick``: 2 repeats, for a smoke test.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import controller_spec, spawn_host, wait_alive  # noqa: E402

from sfl_brain import bus  # noqa: E402
from sfl_brain.bodies.humanoid import JOINT_NAMES, Humanoid  # noqa: E402
from sfl_brain.bodies.humanoid_table import STANDING  # noqa: E402
from sfl_brain.body import Controller, InProcessLink  # noqa: E402
from sfl_brain.host import request  # noqa: E402
from sfl_brain.messages import SensorFrame, TrialRequest  # noqa: E402
from sfl_brain.modules.controllers.cpg import CPGController, CPGParams  # noqa: E402
from sfl_brain.placement import assign, usable_cpus  # noqa: E402
from sfl_brain.scenario import load  # noqa: E402

#: the body's poll for each command in the humanoid's scenario (us), the benchmark's default
SCENARIO = Path(__file__).resolve().parents[1] / "scenarios" / "humanoid_walk.yaml"
SCENARIO_SPIN_US = load(SCENARIO).scenario.lockstep.spin_us

SECONDS = 10.0  # simulated time of a trial
BODY_PARAMS = {"duration": SECONDS}
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


def new_body() -> Humanoid:
    body = Humanoid(Humanoid.Params(**BODY_PARAMS))
    body.logging = False
    return body


def physics_only(body: Humanoid) -> float:
    """(a): 1000 ticks of ``actuate`` with the standing command on a freshly started trial."""
    body.start_trial(REQUEST)
    t = time.perf_counter()
    for _ in range(int(round(SECONDS / body.params.control_dt))):
        body.actuate(STANDING_COMMAND)
    return time.perf_counter() - t


def whole_trial(body: Humanoid) -> tuple[float, dict]:
    """(a') or (b): the body's trial with the controller of its link; the trial must last the full 10 s."""
    t = time.perf_counter()
    result = body.handle(REQUEST)
    elapsed = time.perf_counter() - t
    assert result.metrics["time"] >= SECONDS - 1e-6 and not result.metrics["fell"], result
    return elapsed, {"success": result.success, **result.metrics}


class Processes:
    """(c): the humanoid and the CPG controller, each hosted in its own process as ``sfl run`` hosts them; a trial is a
    request from here, as the supervisor sends it."""

    def __init__(self, session, endpoint: str, run_id: str, placed: dict, spin: float) -> None:
        controller = controller_spec(run_id, "sfl_brain.modules.controllers.cpg:CPGController", endpoint)
        controller.update(params=CONTROLLER_PARAMS, cpus=placed.get("controller"))
        body = controller_spec(run_id, "sfl_brain.bodies.humanoid:Humanoid", endpoint, placed.get("body"))
        body.update(
            instance="body",
            spec_name="body",
            params=BODY_PARAMS,
            routes={SensorFrame.TAG: "controller"},
            spin=spin,
        )
        self.procs = [spawn_host(controller), spawn_host(body)]
        for name in ("controller", "body"):
            wait_alive(session, bus.alive_key(run_id, name))
        self.session, self.key = session, bus.key(run_id, "body", TrialRequest.TAG)

    def trial(self) -> tuple[float, dict]:
        t = time.perf_counter()
        result = request(self.session, self.key, REQUEST, 120.0)
        elapsed = time.perf_counter() - t
        assert result.metrics["time"] >= SECONDS - 1e-6 and not result.metrics["fell"], result
        return elapsed, {"success": result.success, **result.metrics}

    def close(self) -> None:
        for proc in self.procs:
            proc.terminate()
            proc.wait(timeout=10)


def main(argv: list[str] | None = None) -> dict[str, float]:
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument(
        "--spin-us", type=float, default=SCENARIO_SPIN_US, help="lockstep.spin_us (default: the humanoid scenario's)"
    )
    parser.add_argument("--pin", choices=["never", "auto", "always"], default="never", help="lockstep.pin_cpus")
    parser.add_argument("--quick", action="store_true", help="2 repeats: a smoke test")
    args = parser.parse_args(argv)
    repeats = 2 if args.quick else args.repeats
    endpoint = bus.free_endpoint()
    session = bus.open_session([endpoint], [])
    placed = assign(["body", "controller"], usable_cpus(), args.pin)  # as sfl run places one worker and its controller
    physics_body = new_body()
    standing_body = new_body()
    standing_body.link = InProcessLink(Standing())
    cpg_body = new_body()
    cpg_body.link = InProcessLink(CPGController(CPGParams(**CONTROLLER_PARAMS)))
    a, a1, b, c = [], [], [], []
    pair = None
    try:
        pair = Processes(session, endpoint, "benchhumanoid", placed, args.spin_us * 1e-6)
        in_process = whole_trial(cpg_body)[1]  # warm-up: worlds built, caches filled
        over_bus = pair.trial()[1]
        assert over_bus == in_process, (over_bus, in_process)  # the same trial over processes, bit for bit
        whole_trial(standing_body)
        for _ in range(repeats):  # interleaved, so that all see the same machine load
            a.append(physics_only(physics_body))
            a1.append(whole_trial(standing_body)[0])
            b.append(whole_trial(cpg_body)[0])
            c.append(pair.trial()[0])
    finally:
        if pair is not None:
            pair.close()
        session.close()
        for body in (physics_body, standing_body, cpg_body):
            body.close()
    a, a1, b, c = (float(np.median(x)) for x in (a, a1, b, c))
    where = f"spin {args.spin_us:g} us, pin {args.pin}: " + (
        f"body on cores {placed['body']}, controller on {placed['controller']}" if placed else "not pinned"
    )
    print(f"humanoid: one {SECONDS:g}-s trial (1000 control ticks, 4000 physics steps), median of {repeats}, {where}")
    print(f"  (a)  physics only, standing command      {a * 1e3:7.1f} ms  ({SECONDS / a:5.1f}x real time)")
    print(f"  (a') body trial, constant controller     {a1 * 1e3:7.1f} ms  ({SECONDS / a1:5.1f}x real time)")
    print(f"  (b)  CPG + body, one process             {b * 1e3:7.1f} ms  ({SECONDS / b:5.1f}x real time; goal >= 20x)")
    print(f"  (c)  CPG + body over Zenoh               {c * 1e3:7.1f} ms  ({SECONDS / c:5.1f}x real time; goal >= 10x)")
    print(f"  (b)/(a) = {b / a:.2f}   (c)/(b) = {c / b:.2f}   (c)/(a) = {c / a:.2f}")
    print(
        f"  beyond the physics: sensing + framework (a')-(a) = {(a1 - a) * 1e3:.1f} ms, CPG (b)-(a') = "
        f"{(b - a1) * 1e3:.1f} ms, bus (c)-(b) = {(c - b) * 1e3:.1f} ms; CPG + bus (c)-(a) = {(c - a) * 1e3:.1f} ms "
        f"vs physics {a * 1e3:.1f} ms (goal: less)"
    )
    return {"physics": a, "standing_trial": a1, "one_process": b, "processes": c}


if __name__ == "__main__":
    main()
