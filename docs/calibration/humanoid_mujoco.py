"""The MuJoCo humanoid's own constants (bodies/humanoid_mjcf.py): what each does, measured beside PyBullet.

    python docs/calibration/humanoid_mujoco.py [--contact] [--servo] [--walk N] [--noise 0.02]

The MuJoCo body (``physics: mujoco``) is the PyBullet body's table, sensors, servo law and trials; what MuJoCo needs
besides are its contact model and the servo's clutches. Each line printed is a trial in one process:

- **standing** (5 s, every joint held at the standing pose): the load on the feet in the last second (mean +- s.d.,
  of the weight 50.97 N), the energy (5.6) spent holding the crouch, the torso's drift and how far its centre of mass
  sank; PyBullet: 50.9 N +- 0.3, 3.8 J;
- **open loop** (tests/bodies/test_humanoid.py's oscillator gait after CPG-HUMANOID.md §8, 3 seeds, start_noise 0.02):
  time to the 1.5-m line, lateral, energy; PyBullet 8.7-9.0 s;
- **CPG** (the default gait of modules/cpg/circuits/humanoid_nao.yaml, unchanged, ``--walk N`` seeds, start_noise
  ``--noise``): the same; PyBullet 13.6-14.1 s (docs/results/chapter4/humanoid_gait.md).

With no option: the shipped setting on both engines. ``--contact`` varies the contacts' time constant
(``CONTACT_SOLREF``: 5, 10, 20 ms) and the friction cone (pyramidal, MuJoCo's default, or elliptic); ``--servo`` the
clutches' (``SERVO_SOLREF``: 5, 10, 20 ms). A setting is chosen where standing is quiet (s.d. of the feet's load under
1 N) and both gaits walk; the shipped one is 10 ms, elliptic, clutches 5 ms (MuJoCo's floor: 2 physics steps).

The servo is PyBullet's law (speed target ``servo_rate (q_cmd - q)`` within the joint's speed, torque within
``servo_stiffness |q_cmd - q| + 0.05 N m`` and the effort) as a clutch: a tendon q - r whose friction is the torque cap,
to a rotor r turned at the speed target. Before it, the same law as a velocity actuator (torque
``kv (target - dq)`` clipped to the cap, implicitfast): kv = servo_stiffness / servo_rate = 5 stood (51.0 N +- 0.2)
but both gaits fell backward within 1.6 s (the servo too soft in motion: PyBullet's constraint spends up to the cap
to reach the speed target, the actuator only kv per rad/s short of it); kv 10, 20, 50 made the standing robot chatter
or fall (a capped actuator's force is explicit in MuJoCo, a relay between +-cap). Measured 2026-11-27 with this script's
trials on that first version, which was never committed (the first commit has the clutch).
About 1 minute on 2 quiet cores (--contact, --servo: 5 minutes).

``--cost``: where a walking MuJoCo trial's physics goes (docs/results/benchmarks.md, issue 31's 3x goal). The CPG's
commands of one 10-s trial are replayed open loop (as benchmarks/engines.py's (a-walk)) beside the standing command:
per physics step, contacts (``data.ncon``), Newton iterations (``data.solver_niter``) and the constraint solver's
share of ``mj_step`` (``data.timer``); then the walking replay's CPU time (median of 5) and the closed-loop trial's
outcome with MuJoCo's solver options changed one at a time (tolerance, CG, PGS, dense and sparse Jacobian). Nothing
here changes the shipped model. About 1 minute.
"""

from __future__ import annotations

import argparse
import itertools
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
from sfl_brain.bodies import humanoid_mjcf  # noqa: E402
from sfl_brain.bodies.humanoid import SENSORS, Humanoid  # noqa: E402
from sfl_brain.bodies.humanoid_table import TOTAL_MASS  # noqa: E402
from sfl_brain.body import InProcessLink  # noqa: E402
from sfl_brain.messages import TrialRequest  # noqa: E402
from sfl_brain.modules.controllers.cpg import CPGController, CPGParams  # noqa: E402
from tests.bodies.test_humanoid import GAIT, Hold, OpenLoopGait  # noqa: E402

INDEX = {s.name: i for i, s in enumerate(SENSORS)}
FEET = [INDEX[name] for name in ("heel_l", "toe_l", "heel_r", "toe_r")]
WEIGHT = TOTAL_MASS * 9.81


def standing(physics: str) -> str:
    body = Humanoid(Humanoid.Params(physics=physics, duration=5.0))
    body.link = InProcessLink(Hold())
    request = TrialRequest(trial_id=0, seed=0, body_params={}, controller_params={}, log=False)
    body.start_trial(request)
    body.link.controller.configure({}, 0)
    load = []
    while not body.done:
        body.actuate(body.link.controller.pose)
        load.append(sum(body.sense()[FEET]))
    last = np.array(load[-100:])
    sink = body.start_height - (body.torso_position[2] - body.ground_height(body.torso_position[0]))
    out = (
        f"feet {last.mean():5.1f} +- {last.std():4.1f} N of {WEIGHT:.1f}, {body.energy:5.2f} J, "
        f"drift {body.torso_position[0] * 1e3:+5.1f} mm, sank {sink * 1e3:+4.1f} mm, fell {body.fell}"
    )
    body.close()
    return out


def walks(physics: str, controller, controller_params: dict, seeds, noise: float, duration: float) -> str:
    body = Humanoid(Humanoid.Params(physics=physics, duration=duration, start_noise=noise))
    body.link = InProcessLink(controller)
    rows = []
    for seed in seeds:
        request = TrialRequest(trial_id=seed, seed=seed, body_params={}, controller_params=controller_params, log=False)
        rows.append(body.handle(request))
    body.close()
    walked = [r for r in rows if r.success]
    times = [r.metrics["time"] for r in walked]
    out = f"{len(walked)}/{len(rows)} reach 1.5 m"
    if walked:
        lateral = max(abs(r.metrics["lateral"]) for r in walked)
        energy = [r.metrics["energy"] for r in walked]
        out += f" in {min(times):.2f}-{max(times):.2f} s, lateral within {lateral:.2f} m, "
        out += f"{min(energy):.0f}-{max(energy):.0f} J"
    failed = [r for r in rows if not r.success]
    if failed:
        out += "; failed: " + ", ".join(
            f"{'fell' if r.metrics['fell'] else 'lane' if r.metrics['left_lane'] else 'timed out'} at "
            f"{r.metrics['time']:.1f} s"
            for r in failed
        )
    return out


def report(physics: str, walk: int, noise: float, label: str = "") -> None:
    print(f"| {physics} {label} | standing | {standing(physics)} |", flush=True)
    print(
        f"| {physics} {label} | open loop | {walks(physics, OpenLoopGait(), GAIT, range(3), 0.02, 12.0)} |", flush=True
    )
    cpg = CPGController(CPGParams(circuit="humanoid_nao"))
    print(f"| {physics} {label} | CPG | {walks(physics, cpg, {}, range(walk), noise, 20.0)} |", flush=True)


def with_world(**constants):
    """Set humanoid_mjcf's constants (each MuJoCo world is generated from them when a body builds it)."""
    for name, value in constants.items():
        setattr(humanoid_mjcf, name, value)


def solver_cost(repeats: int = 5) -> None:
    """``--cost``: the walking replay's contacts, iterations and solver share, and its cost under other solver
    options (the module's docstring)."""
    import time

    import mujoco

    from benchmarks.humanoid import REQUEST, STANDING_COMMAND, gait_commands

    params = {"duration": 10.0, "physics": "mujoco"}
    recorder = Humanoid(Humanoid.Params(**params))
    recorder.logging = False
    recorder.link = InProcessLink(CPGController(CPGParams(circuit="humanoid_nao")))
    walking = gait_commands(recorder)
    body = Humanoid(Humanoid.Params(**params))
    body.logging = False
    body.link = InProcessLink(CPGController(CPGParams(circuit="humanoid_nao")))
    body.handle(REQUEST)  # builds the flat world
    model, data = body.world.model, body.world.data
    timers = mujoco.mjtTimer

    def replay(commands) -> tuple[float, float, float, float]:
        """CPU s of the replay, mean contacts and iterations a step, the constraint solver's share of mj_step."""
        body.start_trial(REQUEST)
        contacts = iterations = 0.0
        cpu = time.process_time()
        for command in commands:
            body.actuate(command)
            contacts += data.ncon
            iterations += int(data.solver_niter[0])
        cpu = time.process_time() - cpu
        share = data.timer[timers.mjTIMER_CONSTRAINT].duration / max(data.timer[timers.mjTIMER_STEP].duration, 1e-12)
        return cpu, contacts / len(commands), iterations / len(commands), share

    standing = [STANDING_COMMAND] * len(walking)
    print("| replay (10 s, open loop) | CPU ms | contacts a step | Newton iterations a step | solver share of step |")
    print("|---|---|---|---|---|")
    for name, commands in (("standing", standing), ("walking", walking)):
        runs = [replay(commands) for _ in range(repeats)]
        cpu = float(np.median([r[0] for r in runs]))
        _, contacts, iterations, share = runs[-1]
        print(f"| {name} | {cpu * 1e3:.1f} | {contacts:.1f} | {iterations:.2f} | {share:.0%} |")
    shipped = (model.opt.solver, model.opt.tolerance, model.opt.jacobian)
    variants = {
        "shipped (Newton, tolerance 1e-8, Jacobian auto)": {},
        "tolerance 1e-6": {"tolerance": 1e-6},
        "tolerance 1e-5": {"tolerance": 1e-5},
        "CG solver": {"solver": int(mujoco.mjtSolver.mjSOL_CG)},
        "PGS solver": {"solver": int(mujoco.mjtSolver.mjSOL_PGS)},
        "dense Jacobian": {"jacobian": int(mujoco.mjtJacobian.mjJAC_DENSE)},
        "sparse Jacobian": {"jacobian": int(mujoco.mjtJacobian.mjJAC_SPARSE)},
    }
    print("\n| solver option | walking replay, CPU ms | the CPG trial (closed loop): fell, x m | MuJoCo reset it |")
    print("|---|---|---|---|")
    for name, changed in variants.items():
        model.opt.solver, model.opt.tolerance, model.opt.jacobian = shipped
        for key, value in changed.items():
            setattr(model.opt, key, value)
        cpu = float(np.median([replay(walking)[0] for _ in range(repeats)]))
        bad = int(data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number)
        metrics = body.handle(REQUEST).metrics
        bad = max(bad, int(data.warning[mujoco.mjtWarning.mjWARN_BADQACC].number))
        print(f"| {name} | {cpu * 1e3:.1f} | {metrics['fell']}, {metrics['distance']:.2f} | {'yes' if bad else 'no'} |")
    model.opt.solver, model.opt.tolerance, model.opt.jacobian = shipped
    body.close()


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--contact", action="store_true", help="vary the contacts' time constant and friction cone")
    parser.add_argument("--servo", action="store_true", help="vary the clutches' time constant")
    parser.add_argument("--walk", type=int, default=3, help="seeds of the CPG gait")
    parser.add_argument("--noise", type=float, default=0.02, help="the body's start_noise, rad")
    parser.add_argument("--cost", action="store_true", help="where a walking trial's MuJoCo physics goes")
    args = parser.parse_args()
    if args.cost:
        solver_cost()
        return
    shipped = {name: getattr(humanoid_mjcf, name) for name in ("CONTACT_SOLREF", "CONE", "SERVO_SOLREF")}
    print("| engine, setting | trial | outcome |")
    print("|---|---|---|")
    if not (args.contact or args.servo):
        for physics in ("pybullet", "mujoco"):
            report(physics, args.walk, args.noise, "(shipped)" if physics == "mujoco" else "")
    if args.contact:
        for time_constant, cone in itertools.product((0.005, 0.01, 0.02), ("pyramidal", "elliptic")):
            with_world(**{**shipped, "CONTACT_SOLREF": (time_constant, 1.0), "CONE": cone})
            report("mujoco", args.walk, args.noise, f"contact {time_constant * 1e3:g} ms, {cone}")
    if args.servo:
        for time_constant in (0.005, 0.01, 0.02):
            with_world(**{**shipped, "SERVO_SOLREF": (time_constant, 1.0)})
            report("mujoco", args.walk, args.noise, f"clutch {time_constant * 1e3:g} ms")
    with_world(**shipped)


if __name__ == "__main__":
    main()
