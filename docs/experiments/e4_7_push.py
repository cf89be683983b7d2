"""E4.7 (L1430-1437): a push on the walking humanoid's back, with and without switching to non-oscillatory patterns.

    python docs/experiments/e4_7_push.py [--seeds 3] [--times 8 8.5 9 9.17 9.33 9.5 10] [--forces 34] [--after 5]
                                         [--kick JOINT=SIGN ...] [--ball KG]

The thesis (Webots, NAO of 4.3 kg): a ball pushes the walking robot from the back in the walking direction, 34 N for
0.1 s at t = 9 s; the CPG switches from oscillatory to non-oscillatory patterns: both shoulders -> plateau (the arms
move back together), hips -> quiescent (pitch joints in opposite directions, roll joints in the same direction),
knees -> plateau, ankle pitch -> plateau, ankle roll -> quiescent (L1437). It shows the switch, not survival counts.

Here the default gait of ``modules/cpg/circuits/humanoid_nao.yaml`` walks the body (``bodies/humanoid.py``, 5.2 kg:
NAO V4.0's table, not scaled to 4.3 kg) on the flat; the body's push (``push_force`` N for ``push_duration`` s from
``push_time``, horizontal, forward, at the torso's centre of mass) is the ball. The finish line is moved far away
(body parameter ``finish_line`` 1000 m) so that the trial lasts to ``--after`` s after the latest push: a trial
**survives** when the robot has neither fallen nor left the lane by then. Conditions:

- ``walk``: no switch, the gait keeps walking;
- ``switch (detector)``: the controller's pattern switch (``CPGParams.switch``, digest §7.11) fired by its push
  detector: the forward rate of the ``torso_pitch`` input (its change over one 10-ms tick) above ``push_rate``. Not in
  the thesis (§0.8); set to 1.25 x the largest such rate over unpushed walks of the same seeds up to the latest push
  time + ``--after`` (measured by the script first and printed), so that walking alone never fires it;
- ``switch (at push)``: the same switch at the push's start (trigger ``time``): what a perfect detector would do;
- ``continuous switch``: both switches again with the switch's ``theta0: continuous`` (chosen here, not in the
  thesis): the switched joints' theta_0 := angle - G (MN_E - MN_F) at the switch's tick, so that no command jumps
  away from its joint's angle (theta_0 := angle makes the knee commands jump 0.7-1.1 rad: the circuit's reflexes
  command an offset at rest, knees -0.5 rad in humanoid_nao.yaml).

The switch, on all 12 joints (the patterns of L1437, ``patterns.PATTERN_POINTS``): V = q = 0, theta_0 := the measured
angle, a kick of +-1 for 0.2 s (§7.11) whose sign is the direction (L1437; + = into RG-F: toward flexion, as every
joint's gain has the sign that makes MN_E extend it). Directions not in the thesis, chosen here: shoulders + (flexion:
arms back, "together to the back"), hip pitch left +, right - ("opposite directions"), hip rolls both + ("the same
direction"), knees + (flexion: crouch), ankle pitch + (flexion: shins forward, feet flat under a crouch), ankle rolls
+. Every RG-RG coupling of the circuit is silenced at the switch (``inhibit``): "inhibiting the synaptic connection
between CPGs is necessary to get different patterns in different joints" (L1292). ``--kick knee_l=-1`` etc. tries
other directions.

``--ball KG``: each push is a real ball instead (``bodies/humanoid.py``: KG kg thrown from behind at the torso's
centre of mass with the push's momentum, force x 0.1 s, timed to arrive at the push's time); the trial table gives the
forward impulse it delivered.

Also run: no push (does the switched posture stand by itself; the detector must not fire). Prints Markdown tables:
survivals per (condition, push) over the seeds, and each trial's outcome with, at a switch, the largest jump of a
command away from its joint's angle. About 1-2 min on 2 shared cores.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
from sfl_brain.bodies.humanoid import BALL_GAP, JOINT_NAMES, Humanoid  # noqa: E402
from sfl_brain.body import InProcessLink  # noqa: E402
from sfl_brain.messages import TrialRequest  # noqa: E402
from sfl_brain.modules.controllers.cpg import CPGController, CPGParams  # noqa: E402
from sfl_brain.modules.cpg.circuit import read_circuit_data  # noqa: E402

FORCE, PUSH_DURATION, PUSH_TIME = 34.0, 0.1, 9.0  # N, s, s (L1430)
NOISE = 0.02  # rad: the body's start_noise, as the other humanoid experiments
DETECTOR_MARGIN = 1.25  # push_rate = this x the largest forward torso-pitch rate of unpushed walking
#: L1437's patterns
PATTERNS = {
    "shoulder_pitch": "plateau",
    "hip_pitch": "quiescent",
    "hip_roll": "quiescent",
    "knee": "plateau",
    "ankle_pitch": "plateau",
    "ankle_roll": "quiescent",
}
#: each joint's kick (its sign = the direction of its switch, L1437; + = toward flexion): see the docstring
KICKS = {
    "shoulder_pitch_l": 1.0,
    "shoulder_pitch_r": 1.0,
    "hip_pitch_l": 1.0,
    "hip_pitch_r": -1.0,
    "hip_roll_l": 1.0,
    "hip_roll_r": 1.0,
    "knee_l": 1.0,
    "knee_r": 1.0,
    "ankle_pitch_l": 1.0,
    "ankle_pitch_r": 1.0,
    "ankle_roll_l": 1.0,
    "ankle_roll_r": 1.0,
}


def coupled_pairs() -> list[list[str]]:
    """Every joint pair the circuit's RG-RG couplings connect (the switch silences them all)."""
    pairs = []
    for c in read_circuit_data("humanoid_nao")["couplings"]:
        pair = sorted({c["source"].split(".")[0], c["target"].split(".")[0]})
        if len(pair) == 2 and pair not in pairs:
            pairs.append(pair)
    return pairs


def switch_params(
    trigger: str, at: float = 0.0, push_rate: float = 1.0, kicks: dict | None = None, theta0: str = "angle"
) -> dict:
    """The controller's ``switch`` parameter of L1437's reaction (``trigger`` "time" at ``at`` or "push"); ``kicks``
    replaces some joints' kicks (directions) of ``KICKS``; ``theta0`` "angle" (§7.11) or "continuous"."""
    return {
        "trigger": trigger,
        "at": at,
        "push_input": "torso_pitch",
        "push_rate": push_rate,
        "joints": {name: PATTERNS[name[:-2]] for name in KICKS},
        "joint_kicks": {**KICKS, **(kicks or {})},
        "inhibit": coupled_pairs(),
        "theta0": theta0,
    }


def body_for(duration: float) -> Humanoid:
    """The humanoid with its finish line out of reach, so that a trial lasts ``duration`` s unless it fails."""
    body = Humanoid(Humanoid.Params(duration=duration, start_noise=NOISE, finish_line=1000.0))
    body.logging = False
    return body


def trial(body: Humanoid, controller: CPGController, seed: int, push: dict) -> dict:
    """One trial; the outcome, the switch's time (None: no switch) and, at the switch, the largest jump of a command
    away from its joint's measured angle (rad, and the joint), against the largest such gap the tick before."""
    body.link = InProcessLink(controller)
    rows = []
    original = body.actuate
    body.actuate = lambda command: (rows.append((body.t, np.asarray(command) - body.q)), original(command))
    try:
        result = body.handle(TrialRequest(trial_id=seed, seed=seed, body_params=push, controller_params={}, log=False))
    finally:
        body.actuate = original
    m = result.metrics
    events = controller.network.switch_events
    out = {
        "survived": not (m["fell"] or m["left_lane"]),
        "why": "fell" if m["fell"] else "left the lane" if m["left_lane"] else "stood or walked",
        "time": m["time"],
        "distance": m["distance"],
        "switch": events[0].time if events else None,
        "jump": None,
        "impulse": m.get("ball_impulse"),  # a ball's forward impulse on the robot, N s
    }
    if events:
        tick = int(round(events[0].time / body.params.control_dt))  # the first command after the switch
        if 0 < tick < len(rows):
            gap, before = np.abs(rows[tick][1]), np.abs(rows[tick - 1][1])
            out["jump"] = (float(gap.max()), JOINT_NAMES[int(gap.argmax())], float(before.max()))
    return out


def walking_pitch_rate(body: Humanoid, seeds: int) -> float:
    """The largest forward rate of the torso_pitch sensor (change over one tick / tick) in unpushed walks."""
    controller = CPGController(CPGParams(circuit="humanoid_nao"))
    body.link = InProcessLink(controller)
    largest = 0.0
    original = body.actuate
    last = {"pitch": None}

    def actuate(command):
        original(command)
        up = body.torso_turn[2]
        pitch = float(np.arctan2(-up[0], up[2]))
        if last["pitch"] is not None:
            nonlocal largest
            largest = max(largest, (pitch - last["pitch"]) / body.params.control_dt)
        last["pitch"] = pitch

    body.actuate = actuate
    try:
        for seed in range(seeds):
            last["pitch"] = None
            body.handle(TrialRequest(trial_id=seed, seed=seed, body_params={}, controller_params={}, log=False))
    finally:
        body.actuate = original
    return largest


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--times", type=float, nargs="+", default=[8.0, 8.5, 9.0, 9.17, 9.33, 9.5, 10.0])
    parser.add_argument("--forces", type=float, nargs="+", default=[FORCE], help="N (L1430: 34)")
    parser.add_argument("--after", type=float, default=5.0, help="s the robot must last after the latest push")
    parser.add_argument("--kick", action="append", default=[], metavar="JOINT=SIGN", help="another direction")
    parser.add_argument(
        "--ball", type=float, default=0.0, metavar="KG", help="a ball of this mass instead of each push's force"
    )
    args = parser.parse_args()
    kicks = {}
    for item in args.kick:
        joint, value = item.split("=", 1)
        if joint not in KICKS:
            parser.error(f"--kick: expected one of the joints {list(KICKS)}; got {joint!r}")
        kicks[joint] = float(value)
    start = time.perf_counter()
    duration = max(args.times) + args.after
    body = body_for(duration)
    walking = walking_pitch_rate(body, args.seeds)
    push_rate = round(DETECTOR_MARGIN * walking, 2)
    print(
        f"push detector: largest forward torso-pitch rate of unpushed walking over {args.seeds} seeds, "
        f"0-{duration:g} s: {walking:.3f} rad/s; push_rate = {DETECTOR_MARGIN:g} x that = {push_rate:g} rad/s\n"
    )
    detector = CPGParams(circuit="humanoid_nao", switch=switch_params("push", 0.0, push_rate, kicks))
    conditions = {
        "walk": lambda at: CPGController(CPGParams(circuit="humanoid_nao")),
        "switch (detector)": lambda at: CPGController(detector),
        "switch (at push)": lambda at: CPGController(
            CPGParams(circuit="humanoid_nao", switch=switch_params("time", at, kicks=kicks))
        ),
        "continuous switch (detector)": lambda at: CPGController(
            CPGParams(circuit="humanoid_nao", switch=switch_params("push", 0.0, push_rate, kicks, "continuous"))
        ),
        "continuous switch (at push)": lambda at: CPGController(
            CPGParams(circuit="humanoid_nao", switch=switch_params("time", at, kicks=kicks, theta0="continuous"))
        ),
    }
    rows = {}
    pushes = [(0.0, None)] + [(force, at) for force in args.forces for at in args.times]
    for name, make in conditions.items():
        for force, at in pushes:
            # no push: "switch (at push)" switches at 9 s anyway (does the switched posture stand by itself)
            controller = make(PUSH_TIME if at is None else at)
            push = {} if at is None else {"push_force": force, "push_duration": PUSH_DURATION, "push_time": at}
            if at is not None and args.ball > 0:  # the same momentum in a ball, arriving at the push's time
                speed = force * PUSH_DURATION / args.ball
                push = {"ball_mass": args.ball, "ball_speed": speed, "ball_time": max(0.0, at - BALL_GAP / speed)}
            rows[name, force, at] = [trial(body, controller, seed, push) for seed in range(args.seeds)]
    body.close()
    what = f"{PUSH_DURATION:g}-s push" if args.ball <= 0 else f"{args.ball:g}-kg ball carrying each push's impulse"
    print(
        f"### Survivals of a {what} from behind over {args.seeds} seeds: alive "
        f"{args.after:g} s after the latest push (trial {duration:g} s; {time.perf_counter() - start:.0f} s wall)\n"
    )
    head = ["no push"] + [f"{force:g} N at {at:g} s" for force, at in pushes[1:]]
    print(f"| condition | {' | '.join(head)} |")
    print(f"|---|{'---|' * len(pushes)}")
    for name in conditions:
        cells = [f"{sum(r['survived'] for r in rows[name, force, at])}/{args.seeds}" for force, at in pushes]
        print(f"| {name} | {' | '.join(cells)} |")
    print(
        "\n### Each trial: survived (S) or how it failed and when; the switch's time and, at it, the largest command - "
        "angle (rad, joint; the tick before in brackets)\n"
    )
    print("| condition | push | outcomes (seed 0, 1, ...) |")
    print("|---|---|---|")
    for (name, force, at), results in rows.items():
        parts = []
        for r in results:
            what = "S" if r["survived"] else f"{r['why']} at {r['time']:.2f} s"
            extra = f", switch {r['switch']:.2f} s" if r["switch"] is not None else ""
            if r["jump"] is not None:
                extra += f", {r['jump'][0]:.2f} {r['jump'][1]} ({r['jump'][2]:.2f})"
            if r["impulse"] is not None:
                extra += f", ball {r['impulse']:.2f} N s"
            parts.append(f"{what} (x {r['distance']:.2f} m{extra})")
        label = f"{force:g} N at {at:g} s" if at is not None else "none"
        if at is None and name.endswith("(at push)"):
            label = f"none (switch at {PUSH_TIME:g} s)"
        print(f"| {name} | {label} | {'; '.join(parts)} |")


if __name__ == "__main__":
    main()
