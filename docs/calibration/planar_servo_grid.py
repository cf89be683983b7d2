"""The position-servo 8-link walker (``planar_8link_servo``) under its position circuit: calibration and probes.

    python docs/calibration/planar_servo_grid.py seeds [--seeds 8] [--set KEY=VALUE ...]
    python docs/calibration/planar_servo_grid.py grid [--n 9] [--seed 0] [--no-reset] [--set KEY=VALUE ...]
    python docs/calibration/planar_servo_grid.py search [--configs 500] [--rng 21]
    python docs/calibration/planar_servo_grid.py spread [--seeds 8] [--start-noise 0.02]

The thesis drives each joint of its 8-link walker "by a simulated servo motor" (L1201). ``bodies/planar_8link.py``
has two: the voltage walker ``planar_8link`` (the command is the motor voltage, (3.6)) and the servo walker
``planar_8link_servo`` (the command is a target angle, tracked by V = K_p (q_cmd - q) - K_d omega into the same DC
motor). The servo walker's circuit is ``modules/cpg/circuits/planar_8link_servo.yaml``; this script is the probe its
comments quote. Controller and body run in one process (``InProcessLink``), as ``docs/calibration/e4_2_grid.py``.

- ``seeds``: the default pattern (sigma_s, sigma_f) = (2, 2) on the legs, from the 0.3-rad crouch, ``start_noise``
  0.02, seeds 0..n-1, phase resets on and off. A cell reads ``W<steps>`` (no fall and >= 2 steps in 10 s: E4.2's
  success, L1243) with the distance walked, ``s<steps>`` (stood) or ``F<time>`` (fell at that time, s).
- ``grid``: one 10-s trial per cell of an n x n grid over [0, 5]^2 (Tables 4.1-4.3), the pattern on the six leg
  joints (L1286), phase resets on (or off), one seed.
- ``search``: the random search the circuit's values come from (the thesis gives none of them): the hips', knees'
  and ankles' G and theta0, the pelvis set-point and the width and weight of BS/BF into the hips, the PF slopes and
  the servo's K_p, each point tried over 4 seeds with phase resets on and off. A trial counts when it succeeds,
  walks more than 1 m and has at least 4 left heel strikes after 2 s (push_phase needs them). About 25 minutes
  for 500 points.
- ``spread``: how far apart the left heel strikes after 4 s fall over seeds (the body's ``heel_strikes``), for
  both walkers at (2, 2), phase resets off and on: do seeds give starts that differ?

``--set`` overrides a value of the circuit by key path (``joints.0.gain=1.0``), as the controller's
``circuit_overrides``. A 9 x 9 grid takes about a minute on 2 shared cores.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
from sfl_brain.bodies.planar_8link import PlanarWalker8, PlanarWalker8Servo  # noqa: E402
from sfl_brain.body import InProcessLink  # noqa: E402
from sfl_brain.messages import TrialRequest  # noqa: E402
from sfl_brain.modules.controllers.cpg import CPGController, CPGParams  # noqa: E402

LEG_JOINTS = ["hip_l", "hip_r", "knee_l", "knee_r", "ankle_l", "ankle_r"]
CROUCH = -0.3  # rad: the knees' start, as E4.2 (scenarios/e4_2_learn.yaml); hips and ankles half as much
START_NOISE = 0.02  # as the former E4.3-E4.4 script (the scenarios now use 0.05)
SIGMA_RANGE = (0.0, 5.0)  # Tables 4.1-4.3
CIRCUITS = {"planar_8link": PlanarWalker8, "planar_8link_servo": PlanarWalker8Servo}


def run_cell(
    sigma_s: float = 2.0,
    sigma_f: float = 2.0,
    seed: int = 0,
    overrides: dict | None = None,
    phase_reset: bool = True,
    start_noise: float = START_NOISE,
    circuit: str = "planar_8link_servo",
    duration: float = 10.0,
    body_params: dict | None = None,
) -> tuple[bool, dict, PlanarWalker8]:
    """One trial of a walker under its circuit with pattern (sigma_s, sigma_f) on the legs: (success, metrics, the
    body after the trial)."""
    params = CPGParams(
        circuit=circuit, circuit_overrides=overrides or {}, phase_reset=phase_reset, pattern_joints=LEG_JOINTS
    )
    cls = CIRCUITS[circuit]
    body = cls(cls.Params(duration=duration, initial_knee=CROUCH, start_noise=start_noise, **(body_params or {})))
    body.link = InProcessLink(CPGController(params))
    pattern = {"sigma_s": float(sigma_s), "sigma_f": float(sigma_f)}
    result = body.handle(TrialRequest(trial_id=0, seed=seed, body_params={}, controller_params=pattern, log=False))
    return result.success, result.metrics, body


def cell_text(success: bool, metrics: dict, distance: bool = False) -> str:
    if success:
        return f"W{metrics['steps']}" + (f" {metrics['distance']:.2f} m" if distance else "")
    if metrics["fell"]:
        return f"F{metrics['fell_at']:.1f}"
    return f"s{metrics['steps']}"


#: the search's space (modes ``search``): what the circuit's comments call "the probe's search"
SEARCH_SPACE = {
    "g_hip": (0.8, 2.5),  # G of the hips, rad
    "g_knee": (1.0, 4.0),
    "g_ankle": (0.0, 0.6),
    "t_hip": (-0.5, 0.1),  # theta0 of the hips, rad
    "t_knee": (-1.2, -0.2),
    "t_ankle": (-0.25, 0.05),
    "lean": (0.0, 0.2),  # rad: the pelvis set-point of BS/BF (the middle of their thresholds)
    "w_pelvis": (0.0, 3.0),  # BF -> MN_E, BS -> MN_F of the hips
}
SEARCH_CHOICES = {
    "width": (0.04, 0.1, 0.2, 0.4),  # rad: BS/BF go from 10 % to 90 % over this (alpha = 2 ln 9 / width)
    "pf_hk": (2.0, 5.0, 10.0),  # PF alpha of the hips and knees
    "pf_ankle": (5.0, 10.0),
    "servo_gain": (30.0, 50.0, 100.0),  # K_p of the body, V/rad
}


def search_overrides(c: dict) -> dict:
    """Circuit overrides for one point of the search space (the same values on both sides)."""
    data = yaml.safe_load((ROOT / "modules/cpg/circuits/planar_8link_servo.yaml").read_text())
    joints = [j["name"] for j in data["joints"]]
    neurons = [n["name"] for n in data["sensory_neurons"]]
    out: dict = {"joints": {}, "sensory_neurons": {}}
    for i, name in enumerate(joints):
        kind = name.split("_")[0]
        if kind == "trunk":
            continue
        entry = {"gain": c[f"g_{kind}"], "theta0": c[f"t_{kind}"]}
        entry["pf"] = {"alpha": c["pf_ankle"] if kind == "ankle" else c["pf_hk"]}
        if kind == "hip":
            entry["synapses"] = {"BF": {"MN_E": c["w_pelvis"]}, "BS": {"MN_F": c["w_pelvis"]}}
        out["joints"][str(i)] = entry
    alpha = 2 * np.log(9) / c["width"]
    out["sensory_neurons"][str(neurons.index("BS"))] = {"theta": c["lean"] - c["width"] / 2, "alpha": -alpha}
    out["sensory_neurons"][str(neurons.index("BF"))] = {"theta": c["lean"] + c["width"] / 2, "alpha": alpha}
    return out


def search(configs: int, rng_seed: int, seeds: int = 4) -> list[dict]:
    """Random points of SEARCH_SPACE x SEARCH_CHOICES, each tried over ``seeds`` seeds with phase resets on and off
    (stopping at a second failure): a trial counts when it succeeds (E4.2), walks more than 1 m and has at least 4 left
    heel strikes after 2 s. One line per point: its values and how many of the 2 x seeds trials counted."""
    rng = np.random.default_rng(rng_seed)
    out = []
    for _ in range(configs):
        c = {k: float(rng.uniform(*bounds)) for k, bounds in SEARCH_SPACE.items()}
        c.update({k: float(rng.choice(values)) for k, values in SEARCH_CHOICES.items()})
        overrides, counted, failed = search_overrides(c), 0, 0
        for reset in (True, False):
            for seed in range(seeds):
                if failed >= 2:
                    break
                success, metrics, body = run_cell(
                    seed=seed, overrides=overrides, phase_reset=reset, body_params={"servo_gain": c["servo_gain"]}
                )
                strikes = [t for t in body.heel_strikes if t >= 2.0]
                good = success and metrics["distance"] > 1.0 and len(strikes) >= 4
                counted += good
                failed += not good
        out.append({**c, "counted": counted})
        print({k: round(v, 3) for k, v in c.items()}, f"{counted}/{2 * seeds}", flush=True)
    return out


def seeds_table(n: int, overrides: dict) -> str:
    lines = ["| phase resets | " + " | ".join(f"seed {s}" for s in range(n)) + " |", "|---" * (n + 1) + "|"]
    for reset in (True, False):
        cells = [cell_text(*run_cell(seed=s, overrides=overrides, phase_reset=reset)[:2], True) for s in range(n)]
        lines.append(f"| {'on' if reset else 'off'} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def grid_table(n: int, seed: int, overrides: dict, phase_reset: bool = True) -> str:
    values = np.linspace(*SIGMA_RANGE, n)
    counts = {"W": 0, "F": 0, "s": 0}
    lines = ["| sigma_s \\ sigma_f | " + " | ".join(f"{v:g}" for v in values) + " |", "|---" * (n + 1) + "|"]
    for sigma_s in values:
        cells = []
        for sigma_f in values:
            success, metrics, _ = run_cell(sigma_s, sigma_f, seed, overrides, phase_reset)
            text = cell_text(success, metrics)
            counts[text[0]] += 1
            cells.append(text)
        lines.append(f"| {sigma_s:g} | " + " | ".join(cells) + " |")
    lines.append("")
    resets = "on" if phase_reset else "off"
    lines.append(f"{counts['W']} of {n * n} cells walk, {counts['F']} fall, {counts['s']} stand ")
    lines[-1] += f"(seed {seed}, phase resets {resets})."
    return "\n".join(lines)


def strike_spread(n: int, start_noise: float, circuit: str, phase_reset: bool) -> tuple[np.ndarray, float, int]:
    """The first left heel strike at or after 4 s per seed (s; NaN if none), the median gait period (s) and how many
    seeds walked (E4.2's success)."""
    firsts, periods, walked = [], [], 0
    for seed in range(n):
        success, _, body = run_cell(seed=seed, phase_reset=phase_reset, start_noise=start_noise, circuit=circuit)
        walked += success
        strikes = np.array(body.heel_strikes)
        after = strikes[strikes >= 4.0]
        firsts.append(after[0] if len(after) else np.nan)
        late = strikes[strikes >= 2.0]
        if len(late) >= 3:
            periods.append(float(np.median(np.diff(late))))
    return np.array(firsts), float(np.median(periods)) if periods else float("nan"), walked


def spread_table(n: int, start_noise: float) -> str:
    lines = [
        f"start_noise {start_noise:g}, seeds 0-{n - 1}, (sigma_s, sigma_f) = (2, 2), initial_knee {CROUCH:g}",
        "",
        "| circuit | phase resets | walked | T (s) | first left strike after 4 s (s) | spread (s) | spread / T |",
        "|---|---|---|---|---|---|---|",
    ]
    for circuit in CIRCUITS:
        for reset in (False, True):
            firsts, period, walked = strike_spread(n, start_noise, circuit, reset)
            ok = firsts[np.isfinite(firsts)]
            spread = float(np.ptp(ok)) if len(ok) else float("nan")
            shown = " ".join(f"{t:.2f}" for t in firsts)
            lines.append(
                f"| {circuit} | {'on' if reset else 'off'} | {walked}/{n} | {period:.3f} | {shown} | {spread:.3f} | "
                f"{spread / period:.2f} |"
            )
    return "\n".join(lines)


def parse_sets(items: list[str]) -> dict:
    out: dict = {}
    for item in items:
        key, _, value = item.partition("=")
        node = out
        parts = key.split(".")
        for part in parts[:-1]:
            node = node.setdefault(part, {})
        node[parts[-1]] = yaml.safe_load(value)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mode", choices=("seeds", "grid", "search", "spread"))
    ap.add_argument("--configs", type=int, default=500, help="search: points to try")
    ap.add_argument("--rng", type=int, default=21, help="search: the generator's seed")
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--n", type=int, default=9)
    ap.add_argument("--no-reset", action="store_true", help="grid: phase resets off")
    ap.add_argument("--start-noise", type=float, default=START_NOISE)
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="circuit override by key path")
    args = ap.parse_args()
    overrides = parse_sets(args.set)
    if args.mode == "seeds":
        print(seeds_table(args.seeds, overrides))
    elif args.mode == "grid":
        print(grid_table(args.n, args.seed, overrides, not args.no_reset))
    elif args.mode == "search":
        search(args.configs, args.rng)
    else:
        print(spread_table(args.seeds, args.start_noise))


if __name__ == "__main__":
    main()
