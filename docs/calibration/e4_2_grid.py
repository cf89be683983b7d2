"""E4.2 groundwork: which (sigma_s, sigma_f) of the thesis's range walk the 8-link walker, one trial per cell.

    python docs/calibration/e4_2_grid.py [--n 9] [--initial-knee -0.3] [--set KEY=VALUE ...]
                                         [--out docs/results/chapter4/e4_2_grid.md]

E4.2 (L1237-1260) learns the RG pattern (sigma_s, sigma_f) in [0, 5]^2 (Tables 4.1-4.3). One pattern is given to
the six leg joints while their CPGs are coupled ("the same pattern in all joints", L1286). The trunk keeps its
circuit's quiescent cell. A trial is a success when the walker "did not fall during the time window [10 s] and
achieved two steps at least" (L1243). Before learning makes sense, part of the space has to walk and part has to
fail. This script maps an n x n grid over [0, 5]^2 with one 10-s trial per cell. The walker is deterministic, so
one trial per cell is the cell's outcome. Controller and body run in one process (``InProcessLink``) with the
shipped circuit ``modules/cpg/circuits/planar_8link.yaml`` and the walker's defaults, from a crouch of
``--initial-knee`` rad (as ``scenarios/e4_2_learn.yaml``).

``--set`` overrides a value of the circuit by key path (``joints.0.gain=20``,
``sensory_neurons.20.theta=0.08``), as the controller's ``circuit_overrides``. The tuning sweeps quoted in the
circuit's comments were made this way.

Each cell reads ``W<steps>`` (a success: no fall, at least two steps), ``s<steps>`` (stood 10 s with fewer than
two steps: a failure without a fall) or ``F<time>`` (fell at that time, s). The script prints the Markdown table
and, with ``--out``, writes it. A 9 x 9 grid takes about 15 s on 2 shared cores: a fall ends a trial early.
"""

from __future__ import annotations

import argparse
import datetime
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
from sfl_brain.bodies.planar_8link import PlanarWalker8  # noqa: E402
from sfl_brain.body import InProcessLink  # noqa: E402
from sfl_brain.messages import TrialRequest  # noqa: E402
from sfl_brain.modules.controllers.cpg import CPGController, CPGParams  # noqa: E402

#: the joints E4.2's pattern is given to (as scenarios/e4_2_learn.yaml): the legs; the trunk keeps its circuit's
#: quiescent cell (its circuit, Fig. 4.12, only keeps the pelvis upright, L1221)
LEG_JOINTS = ["hip_l", "hip_r", "knee_l", "knee_r", "ankle_l", "ankle_r"]
SIGMA_RANGE = (0.0, 5.0)  # Tables 4.1-4.3


def run_cell(
    sigma_s: float,
    sigma_f: float,
    overrides: dict | None = None,
    initial_knee: float = -0.3,
    duration: float = 10.0,
) -> tuple[bool, dict]:
    """One trial of the walker driven by the planar circuit with pattern (sigma_s, sigma_f) on the legs:
    (success, the body's metrics)."""
    params = CPGParams(circuit="planar_8link", circuit_overrides=overrides or {}, pattern_joints=LEG_JOINTS)
    body = PlanarWalker8(PlanarWalker8.Params(duration=duration, initial_knee=initial_knee))
    body.link = InProcessLink(CPGController(params))
    request = TrialRequest(
        trial_id=0,
        seed=0,
        body_params={},
        controller_params={"sigma_s": float(sigma_s), "sigma_f": float(sigma_f)},
        log=False,
    )
    result = body.handle(request)
    return result.success, result.metrics


def cell_text(success: bool, metrics: dict) -> str:
    if success:
        return f"W{metrics['steps']}"
    if metrics["fell"]:
        return f"F{metrics['fell_at']:.1f}"
    return f"s{metrics['steps']}"


def grid_map(n: int, overrides: dict, initial_knee: float) -> tuple[np.ndarray, dict]:
    """The n x n grid: the values, and {(sigma_s, sigma_f): (success, metrics)}."""
    values = np.linspace(*SIGMA_RANGE, n)
    cells = {}
    for sigma_f in values:
        for sigma_s in values:
            cells[(float(sigma_s), float(sigma_f))] = run_cell(sigma_s, sigma_f, overrides, initial_knee)
    return values, cells


def markdown(values: np.ndarray, cells: dict, note: str) -> str:
    head = "| sigma_f \\ sigma_s | " + " | ".join(f"{v:.3g}" for v in values) + " |"
    rule = "|" + "---|" * (len(values) + 1)
    rows = [
        f"| **{sigma_f:.3g}** | " + " | ".join(cell_text(*cells[(float(s), float(sigma_f))]) for s in values) + " |"
        for sigma_f in values[::-1]
    ]
    outcomes = list(cells.values())
    walked = [m for ok, m in outcomes if ok]
    falls = sum(m["fell"] for _, m in outcomes)
    stood = len(outcomes) - len(walked) - falls
    summary = (
        f"{len(walked)} of {len(outcomes)} cells walk ({100 * len(walked) / len(outcomes):.0f} %), {falls} fall, "
        f"{stood} stand 10 s without two steps."
    )
    if walked:
        speeds = [m["velocity"] for m in walked]
        steps = [m["steps"] for m in walked]
        summary += (
            f" Walking cells: {min(steps)}-{max(steps)} steps in 10 s, "
            f"{min(speeds):.2f}-{max(speeds):.2f} m/s (hip's mean speed)."
        )
    return "\n".join([note, "", head, rule, *rows, "", summary, ""])


PREFACE = """# E4.2 groundwork: which patterns walk the 8-link walker

- **Command:** `python docs/calibration/e4_2_grid.py --out docs/results/chapter4/e4_2_grid.md`
  (about 15 s on 2 shared cores).
- **Run:** {date}, git HEAD `{head}`.

E4.2 (L1237-1260) learns the RG pattern (sigma_s, sigma_f) in [0, 5]^2. The learnt pattern goes to every leg joint,
and the joints stay coupled (L1286). A trial succeeds if the walker does not fall within 10 s and makes at least two
steps (L1243). Learning only makes sense if part of the space walks and part fails, so this map runs one trial per
cell of a grid. Controller: `cpg`, circuit `modules/cpg/circuits/planar_8link.yaml`. Body: `planar_8link`, from a
0.3-rad knee crouch, feet together. These are the settings of `scenarios/e4_2_learn.yaml`. One trial per cell is that
cell's outcome, with a caveat: the walker is deterministic for given commands (a replay of recorded commands gives the
same trial to the bit), but its CoM - CoP sensor (`fall`) sums the contacts in pymunk's arbiter order, which changes
from run to run, so it differs in its last bit now and then (1e-16 m), and the closed loop can grow that. Three runs
of this map gave the same outcome in every cell (so did 2 runs with the PF fed V). With the ankles at 40 V (tried
for issue 23, not shipped) cell (3.75, 3.12), at the walk / fall border, read W20, F9.0, F9.3 and W20 over 4 runs.

With the thesis's tables and the circuit's first values (5-V joint gains, BS/BF only on the trunk), the walker fell
backward in 1.4 s at (2, 2). Three choices the thesis leaves open make it walk; the circuit file gives each one's
reason and sweep:

- the joint gains, M of (3.6): 30 V instead of 5 V. The (n + 1) averaging of (4.12) keeps MN_E - MN_F within
  +-0.47, so 5 V gave at most 14 N m.
- BS/BF (pelvis to vertical, L1221) also go into the hip motor neurons (BF -> MN_E, BS -> MN_F, weight 2). The hip
  circuit, Fig. 4.11, has no text. Without this no cell walks: the antiphase hip rhythm cancels on the pelvis, which
  topples over the hips.
- BS/BF are centred on a pelvis leaning 0.15 rad forward, not upright.

Everything else is the thesis's (Tables 4.1-4.3, ES/FS at mid-range with the minimum slope of L1135, FB/FF and
GB/GF into the ankle PF) or the digest's (phase resetting on, §7.10). The PF reads the RG's bounded output
tanh(V / A_f) with slopes 8.6 (hips, knees) and 10 (ankles) (`pf_input: bounded`, issue 23; the circuit file has the
reasons). With the PF fed V itself (slopes 1 and 5) 29 cells walked, 36 fell and 16 stood. The two maps give a
different outcome in 16 cells, 10 of them fast oscillators (sigma_s >= 3.75): 6 walk that fell (among them (3.75, 5),
(5, 5), (5, 4.38) and (5, 3.75): at sigma_s = 5 the walker fell within 3.5 s wherever sigma_f >= 1.25), 7 fall that
walked (five of them late, after 6.9-9.4 s), and 3 change between standing and falling. The slow oscillators'
walking band (sigma_s 1.25-3.12) is the same but for 4 cells.
"""


READING = """How to read it, with the classes of the single-cell map (digest §1.7;
docs/results/chapter4/e4_1_patterns.md):

- Quiescent and almost-oscillating cells (sigma_f <= 0.625) make no steps. The hips pitch the pelvis to its forward
  set-point and the walker falls forward.
- Plateau cells (sigma_s = 0, and sigma_s small below the line sigma_s = (sigma_f - 1) / 2) hold the legs
  apart after the start kick. The walker stands there without stepping: a failure without a fall.
- Oscillators from sigma_s = 0.625 to 3.1 walk: the slower ones (periods 1-2 s) over most of the sigma_f range.
- Fast oscillators (sigma_s >= 3.75, periods below about 0.8 s) fall in 13 of their 21 cells with sigma_f >= 1.25,
  11 of them late (after 5.8-9.4 s), two at sigma_f = 1.25 within 2.1 s (with the PF fed V, the walker sat down
  backward within 2.3 s at sigma_s = 5). At
  sigma_s = 5 and sigma_f >= 3.75 they walk, with 23-25 steps in 10 s.
"""


def parse_set(items: list[str]) -> dict:
    out = {}
    for item in items:
        key, _, value = item.partition("=")
        out[key] = yaml.safe_load(value)
    return out


def git_head() -> str:
    """The checkout's commit (read only), or "unknown"."""
    try:
        done = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True)
    except OSError:
        return "unknown"
    return done.stdout.strip() or "unknown"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=9, help="grid points per axis over [0, 5]")
    ap.add_argument("--initial-knee", type=float, default=-0.3, help="the walker's starting crouch, rad")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="a circuit override")
    ap.add_argument("--out", type=Path, help="write the Markdown table here")
    args = ap.parse_args()
    overrides = parse_set(args.set)
    start = time.perf_counter()
    values, cells = grid_map(args.n, overrides, args.initial_knee)
    wall = time.perf_counter() - start
    what = f"circuit planar_8link{' with ' + str(overrides) if overrides else ''}"
    note = (
        f"{args.n} x {args.n} grid, one 10-s trial per cell, {what}, initial_knee {args.initial_knee:g} rad; "
        f"rows sigma_f (top = 5), columns sigma_s. W<n> = walked (no fall, n >= 2 steps), "
        f"s<n> = stood 10 s with n < 2 steps, F<t> = fell at t s. {wall:.0f} s wall."
    )
    text = markdown(values, cells, note)
    if not overrides:
        text = PREFACE.format(date=datetime.date.today().isoformat(), head=git_head()) + "\n" + text + "\n" + READING
    print(text)
    if args.out:
        args.out.write_text(text)


if __name__ == "__main__":
    main()
