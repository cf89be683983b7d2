"""Stance-onset states for state phase resets, taken from the unperturbed gait (thesis L1270-1282, digest §7.10).

    python -m sfl_brain.modules.cpg.calibrate stance CIRCUIT [--body planar_8link] [--seconds 10] [--after 2]
        [--refractory 0.4] [--leg GB_l=hip_l,knee_l,ankle_l ...] [--seed 0]

A ``phase_resets`` entry with ``mode: state`` makes a leg's RGs jump, at its heel strike, to a stored state: the state
those RGs have at heel strike in the unperturbed gait, so that a reset leaves an unperturbed walker as it is and puts
a perturbed one back at stance onset. This module measures that state: it runs the body with the CPG controller in
one process (``InProcessLink``), phase resets off, no push, from the scenario's start (the 8-link walker crouched at
``initial_knee`` = -0.3 rad, as ``scenarios/e4_2_learn.yaml``), records the RG state (V, q of E and F) of each leg's
joints at the start of every tick in which that leg's heel strikes, by the rule the reset itself uses
(``network.ResetTrigger``: the sensory neuron rising through its threshold, not within ``refractory`` s of the last
strike, not before ``after`` s), and prints the mean over the strikes, with its spread (the standard deviation over
strikes: small when the gait is periodic), as a ``phase_resets`` YAML snippet.

**Re-run it whenever the circuit's gait changes** (its patterns, gains, couplings, reflexes, kicks; the body; the
start): the stored state belongs to one gait, and a reset to another gait's state is a perturbation, not a reset.

The legs: each of the circuit's ``phase_resets`` entries (its sensor, its pulse joint, and its ``joints``, or else
every joint with the pulse joint's side suffix: ``hip_l`` -> ``hip_l, knee_l, ankle_l``), or ``--leg
SENSOR=JOINT,...`` (the first joint takes the pulses; the threshold 0.5 of §7.10 unless the circuit has an entry on
that sensor).
"""

from __future__ import annotations

import argparse
import shlex
import sys
from dataclasses import dataclass

import numpy as np

from .circuit import Circuit, PhaseReset
from .network import E, F, ResetTrigger

#: bodies the calibration can run, and their start (the scenarios' own)
BODIES = {
    "planar_8link": ("sfl_brain.bodies.planar_8link", "PlanarWalker8", {"initial_knee": -0.3}),  # e4_2_learn.yaml
    "humanoid": ("sfl_brain.bodies.humanoid", "Humanoid", {"finish_line": 1000.0}),  # walks on, no finish
}
REFRACTORY = 0.4  # s: chosen here; the 8-link walker's heel bounces about 0.05 s after landing, its cycle is ~1.35 s


@dataclass(frozen=True)
class Leg:
    """Where to take a stance-onset state: the heel sensor's neuron, the joint a pulse would go into, the joints whose
    RGs are recorded (and later reset), the threshold of the rising edge."""

    sensor: str
    joint: str
    joints: tuple[str, ...]
    threshold: float = 0.5
    amplitude: float = -1.0
    duration: float = 0.04


@dataclass(frozen=True)
class StanceState:
    """A leg's stance-onset state: ``mean`` and ``spread`` (s.d. over the strikes) of each joint's {E: (V, q), F: (V,
    q)}, and ``swing``, how far each of them ranges over the gait (peak to peak after ``after``, the scale the spread is
    small against); the strike times (s) it was averaged over, and the trigger's ``refractory`` and ``after`` (s)."""

    leg: Leg
    strikes: tuple[float, ...]
    mean: dict[str, dict[str, tuple[float, float]]]
    spread: dict[str, dict[str, tuple[float, float]]]
    swing: dict[str, dict[str, tuple[float, float]]]
    refractory: float
    after: float

    def largest_spread(self) -> tuple[float, float]:
        """The largest s.d. over strikes of any V and of any q of the leg (the model's mV)."""
        cells = [cell for joint in self.spread.values() for cell in joint.values()]
        return max(c[0] for c in cells), max(c[1] for c in cells)

    def largest_relative_spread(self) -> tuple[float, float]:
        """The largest s.d. over strikes of any V and of any q, as a fraction of its swing over the gait."""
        ratios = [
            (sd[0] / sw[0], sd[1] / sw[1])
            for joint in self.spread
            for sd, sw in zip(self.spread[joint].values(), self.swing[joint].values(), strict=True)
        ]
        return max(r[0] for r in ratios), max(r[1] for r in ratios)

    def entry(self) -> dict:
        """This state as a ``phase_resets`` entry (``mode: state``)."""
        leg = self.leg
        return {
            "sensor": leg.sensor,
            "joint": leg.joint,
            "mode": "state",
            "joints": list(leg.joints),
            "threshold": leg.threshold,
            "refractory": self.refractory,
            "after": self.after,
            "amplitude": leg.amplitude,
            "duration": leg.duration,
            "state": {j: {side: [round(v, 4) for v in cell] for side, cell in s.items()} for j, s in self.mean.items()},
        }


def legs_of(circuit: Circuit, given: dict[str, list[str]] | None = None) -> list[Leg]:
    """The legs to calibrate: ``given`` (sensor -> joints) or the circuit's phase resets (see the module docstring)."""
    by_sensor: dict[str, PhaseReset] = {r.sensor: r for r in circuit.phase_resets}
    if given:
        out = []
        for sensor, joints in given.items():
            r = by_sensor.get(sensor)
            keep = {"threshold": r.threshold, "amplitude": r.amplitude, "duration": r.duration} if r else {}
            out.append(Leg(sensor, r.joint if r else joints[0], tuple(joints), **keep))
        return out
    if not circuit.phase_resets:
        raise ValueError(f"circuit {circuit.name} has no phase_resets: name the legs (--leg SENSOR=JOINT,...)")
    out = []
    for r in circuit.phase_resets:
        if r.joints is not None:
            joints = tuple(r.joints)
        else:
            side = r.joint[r.joint.rfind("_") :] if "_" in r.joint else r.joint
            joints = tuple(j.name for j in circuit.joints if j.name.endswith(side))
        out.append(Leg(r.sensor, r.joint, joints, r.threshold, r.amplitude, r.duration))
    return out


def stance_states(
    circuit: str = "planar_8link",
    body: str = "planar_8link",
    seconds: float = 10.0,
    after: float = 2.0,
    refractory: float = REFRACTORY,
    legs: dict[str, list[str]] | None = None,
    overrides: dict | None = None,
    seed: int = 0,
) -> list[StanceState]:
    """Run ``body`` with the CPG controller on ``circuit`` (its ``overrides`` applied) for ``seconds`` s, phase resets
    off, and return each leg's mean RG state at its heel strikes after ``after`` s (see the module docstring).
    ValueError when the walker falls or a leg strikes fewer than twice after ``after``."""
    import importlib

    from sfl_brain.body import InProcessLink
    from sfl_brain.messages import TrialRequest
    from sfl_brain.modules.controllers.cpg import CPGController, CPGParams

    if body not in BODIES:
        raise ValueError(f"body: expected one of {sorted(BODIES)}; got {body!r}")
    module, name, start = BODIES[body]
    body_cls = getattr(importlib.import_module(module), name)

    class Recorder(CPGController):
        """The controller, keeping the RG state at the start of each tick and the tick's sensory neurons."""

        def configure(self, params: dict, seed: int) -> None:
            super().configure(params, seed)
            self.states: list[np.ndarray] = []
            self.rho: list[np.ndarray] = []

        def step(self, sensors: np.ndarray) -> np.ndarray:
            before = self.network.y[0].copy()  # (V, q) x neurons, before this tick's integration
            commands = super().step(sensors)
            self.states.append(before)
            self.rho.append(self.network.sensory)  # sampled at this tick's start
            return commands

    params = CPGParams(circuit=circuit, circuit_overrides=overrides or {}, phase_reset="off")
    controller = Recorder(params)
    walker = body_cls(body_cls.Params(duration=seconds, **start))
    walker.link = InProcessLink(controller)
    result = walker.handle(TrialRequest(trial_id=0, seed=seed, body_params={}, controller_params={}, log=False))
    walker.close()
    if result.metrics.get("fell"):
        at = result.metrics.get("fell_at")
        raise ValueError(f"the unperturbed gait of {circuit} on {body} falls (at {at} s): no gait to take a state from")
    net = controller.network
    chosen = legs_of(net.circuit, legs)
    for leg in chosen:
        for joint in (leg.sensor, *leg.joints):
            pool = net.sensor_names if joint == leg.sensor else net.joint_names
            if joint not in pool:
                raise ValueError(f"leg {leg.sensor}: {joint!r} is not one of {pool}")
    trigger = ResetTrigger(
        [leg.threshold for leg in chosen], [refractory] * len(chosen), [after] * len(chosen), batch=1
    )
    sensors = [net.sensor_names.index(leg.sensor) for leg in chosen]
    strikes: list[list[int]] = [[] for _ in chosen]
    dt = controller.trial.dt
    for tick, rho in enumerate(controller.rho):
        fired = trigger(rho[sensors][None, :], tick * dt)
        for n in np.flatnonzero(fired[0]) if fired is not None else ():
            strikes[n].append(tick)
    states = np.array(controller.states)  # (ticks, 2, neurons)
    swings = np.ptp(states[int(round(after / dt)) :], axis=0)  # (2, neurons): V and q peak to peak over the gait
    out = []
    for leg, ticks in zip(chosen, strikes, strict=True):
        if len(ticks) < 2:
            raise ValueError(
                f"leg {leg.sensor}: {len(ticks)} heel strike(s) after {after} s in {seconds} s; run longer (--seconds)"
            )
        at = states[ticks]  # (strikes, 2, neurons)
        mean, spread, swing = {}, {}, {}
        for joint in leg.joints:
            j = net.joint_names.index(joint)
            swing[joint] = {s: tuple(float(x) for x in swings[:, 2 * j + k]) for s, k in (("E", E), ("F", F))}
            mean[joint] = {
                s: tuple(float(x) for x in at[:, :, 2 * j + k].mean(axis=0)) for s, k in (("E", E), ("F", F))
            }
            spread[joint] = {
                s: tuple(float(x) for x in at[:, :, 2 * j + k].std(axis=0)) for s, k in (("E", E), ("F", F))
            }
        out.append(StanceState(leg, tuple(round(t * dt, 6) for t in ticks), mean, spread, swing, refractory, after))
    return out


def snippet(states: list[StanceState], header: str = "") -> str:
    """The states as a ``phase_resets:`` YAML snippet, with the strikes and the spread as comments."""
    lines = [f"# {line}" for line in header.splitlines()]
    for s in states:
        (v, q), (rv, rq) = s.largest_spread(), s.largest_relative_spread()
        times = ", ".join(f"{t:g}" for t in s.strikes)
        lines.append(f"# {s.leg.sensor}: mean over {len(s.strikes)} strikes at {times} s;")
        lines.append(
            f"#   spread (s.d. over strikes) V <= {v:.3f}, q <= {q:.3f}: {100 * rv:.1f}% and {100 * rq:.1f}% of their "
            "swing over the gait"
        )
    lines.append("phase_resets:")
    for s in states:
        e = s.entry()
        lines.append(f"  - sensor: {e['sensor']}")
        for key in ("joint", "mode", "threshold", "refractory", "after", "amplitude", "duration"):
            lines.append(f"    {key}: {e[key]}")
        lines.append(f"    joints: [{', '.join(e['joints'])}]")
        lines.append("    state:")
        for joint, cell in e["state"].items():
            lines.append(f"      {joint}: {{E: [{cell['E'][0]}, {cell['E'][1]}], F: [{cell['F'][0]}, {cell['F'][1]}]}}")
    return "\n".join(lines) + "\n"


def _leg(text: str) -> tuple[str, list[str]]:
    sensor, sep, joints = text.partition("=")
    if not sep or not sensor or not joints:
        raise argparse.ArgumentTypeError(f"expected SENSOR=JOINT,JOINT,...; got {text!r}")
    return sensor, joints.split(",")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m sfl_brain.modules.cpg.calibrate", description=__doc__.split("\n")[0]
    )
    commands = parser.add_subparsers(dest="command", required=True)
    stance = commands.add_parser("stance", help="stance-onset states of a circuit's gait, as a phase_resets snippet")
    stance.add_argument("circuit", help="a shipped circuit (modules/cpg/circuits) or a YAML file")
    stance.add_argument("--body", default="planar_8link", choices=sorted(BODIES))
    stance.add_argument("--seconds", type=float, default=10.0, help="s of unperturbed walking")
    stance.add_argument("--after", type=float, default=2.0, help="s: strikes before it are the start's transient")
    stance.add_argument("--refractory", type=float, default=REFRACTORY, help="s: a strike within it is a bounce")
    stance.add_argument("--leg", type=_leg, action="append", help="SENSOR=JOINT,... (default: the circuit's resets)")
    stance.add_argument("--seed", type=int, default=0, help="the trial seed (the body's start_noise, if any)")
    args = parser.parse_args(argv)
    try:
        states = stance_states(
            args.circuit,
            args.body,
            args.seconds,
            args.after,
            args.refractory,
            dict(args.leg) if args.leg else None,
            seed=args.seed,
        )
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    given = sys.argv[1:] if argv is None else argv
    header = (
        f"stance-onset states of circuit {args.circuit} on body {args.body}: its unperturbed gait (phase resets off,\n"
        f"no push), {args.seconds:g} s, strikes after {args.after:g} s. Re-run whenever the gait changes:\n"
        f"python -m sfl_brain.modules.cpg.calibrate {' '.join(shlex.quote(a) for a in given)}"
    )
    sys.stdout.write(snippet(states, header))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
