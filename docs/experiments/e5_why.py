"""Why two of issue 29's cases still differ from the thesis, read from chapter 5's runs (no new walk):

1. **The convex edges** (flat -> down, up -> flat): per walk of ``detectors{TAG}_s0..2``, the time after a foot first
   touched the next piece of ground (the body's ``events/terrain``) until a foot's sensed slope came within 3 deg of
   the new piece's slope (``controller/terrain/slope_l``, ``_r``), the feet detector and the torso band fired
   (``controller/events/detector``), and the torso pitched past 10 deg (``body/torso/pitch``), medians per case; and
   how many walks' feet detector fired before the estimate reached the new slope and before the torso passed 10 deg.
2. **Downhill -> flat without switching**: per seed and neuron choice, the learnt downhill neuron (``switch{TAG}_sN``'s
   ``down_without`` trials), its walks onto the flat, and the share of its 8 nearest cells of the flat pre-sweep
   (``presweep``, in the space's unit cube) that walked the flat.
3. **The feet's contacts at the edges** (the candidate named after 1: a foot overhanging a convex edge presses with
   its heel or toe alone): per walk, each foot's heel-only and toe-only contact (``body/feet/heel_*``, ``toe_*`` >=
   0.5) and the share of ticks with one point of contact of the four, averaged over the last ``CONTACT_WINDOW`` s;
   the largest value any flat walk of the same runs that did not fall shows after its start ramp (5 s on) is that
   pattern's band, and a pattern "fires" when it first exceeds it after the touch. Per case: walks where it fires,
   the median latency, and how many fire within 0.5 s of the touch and before the torso passes 10 deg.
4. **The weight shared between the feet** (the next candidate: a foot over a convex edge takes its share of the
   weight late, so the feet go longer without sharing it): per walk, the time since both feet last carried at least
   a share ``x`` of their summed pressure (heel + toe of each), counted from 5 s on, for x in ``SHARES``; its band and
   firing as in 3.
5. **A foot on its heel alone, pitched past the ground it walked on** (a foot whose heel has landed beyond a convex
   edge rotates toe-down past the old ground before its toe finds the new one; at a concave edge, a foot on its toe
   alone rotates toe-up past it): per walk, the most any foot on its heel alone pitches toe-down past the slope of the
   piece walked before the edge (deg; the sole's pitch is the torso's plus the leg's pitch joints, as the ankle
   adaptation reads it), and the same for a foot on its toe alone pitching toe-up; band and firing as in 3.
6. **Anything the body senses that the flat walks do not show** (a generic detector: if any sensed signal changed at
   a convex edge before the robot pitched over, this would see it): per walk that starts on the flat, the
   Mahalanobis distance of the sensed state (the ten leg joints, the four feet signals, the torso's pitch, roll and
   their rates) from the flat walks' mean at the same gait phase (eight bins of the left hip's oscillation), the model
   fitted on the other two seeds' flat walks that stayed up (from 5 s on), averaged over 3 samples; band and firing
   as in 3. The walks that start on a ramp are left out (they are far from a flat model from their first step).
7. **The line between the feet** (a convex edge puts the front foot lower than the back one): per tick with both
   feet pressing, the slope of the line between each foot's pressed points (heel, toe or their middle; the legs'
   kinematics from the table and the torso's pitch and roll), fore and aft, against the slope walked before the edge,
   counted where the feet are at least ``SPACING`` apart fore and aft; band and firing as in 3. And how far apart the
   feet are fore and aft in double support on the flat walks.

    python docs/experiments/e5_why.py runs/chapter5
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pyarrow.parquet as pq

from sfl_brain.bodies.humanoid_table import FSR_X, HIP, SOLE, THIGH, TIBIA
from sfl_brain.recording.recorded import read_events, read_series
from sfl_brain.report.terrain import detector_of

#: each walk's case (e5_detectors.yaml) and the slope of the ground it walks onto, deg
NEW_SLOPE = {"flatdown": -10.0, "upflat": 0.0, "up": 10.0, "down": 0.0}
#: the slope of the ground each case walks before the edge, deg (the flat walks' too)
OLD_SLOPE = {"flat": 0.0, "flatdown": 0.0, "upflat": 10.0, "up": 0.0, "down": -10.0}
#: the joints whose angles, added to the torso's pitch, give a sole's pitch in the world (+ = toe down)
CHAIN = ("hip_pitch", "knee", "ankle_pitch")
NEAR_DEG = 3.0  # a foot senses the new slope: its estimate within this of the new piece's slope
TORSO_DEG = 10.0
CONTACT_WINDOW = 0.33  # s, half a gait cycle (0.667 s): a foot's stance
PRESSED = 0.5  # a heel or toe sensor at or above this presses (the adaptation's lying-flat test, circuit file)
SETTLED = 5.0  # s: a walk's contacts count toward the band from here (after the 4-s start ramp)
FEET = ["body/feet/heel_l", "body/feet/toe_l", "body/feet/heel_r", "body/feet/toe_r"]
SHARES = (0.1, 0.2, 0.3, 0.4)  # the lighter foot's share of the feet's summed pressure that counts as sharing
#: the sensed state of 6. and 7.: the leg joints, the feet (pressures clipped at NOVELTY_PRESS N and scaled in 6.), the
#: torso
LEG = ("hip_roll", "hip_pitch", "knee", "ankle_pitch", "ankle_roll")  # from the torso down
JOINTS = [f"body/joints/{joint}_{side}" for joint in LEG for side in "lr"]
TORSO = ["body/torso/pitch", "body/torso/pitch_rate", "body/torso/roll", "body/torso/roll_rate"]
STATE = JOINTS + FEET + TORSO
NOVELTY_PRESS, PHASES, GAIT_HZ = 30.0, 8, 1.5
SPACING = (0.03, 0.05)  # m: the feet's fore-and-aft distance from which the line between them counts (7.)


def table(path: Path) -> list[dict]:
    return pq.read_table(path).to_pylist()


def median(values) -> float:
    return float(np.median(values)) if len(values) else float("nan")


def edge_times(runs: Path, tag: str) -> list[dict]:
    rows = []
    for seed in range(3):
        run = runs / f"detectors{tag}_s{seed}"
        trials = table(run / "trials.parquet")
        rrd = run / "recording.rrd"
        feet = ["controller/terrain/slope_l", "controller/terrain/slope_r"]
        series = read_series(rrd, [*feet, "body/torso/pitch"])
        events = read_events(rrd, ["body/events/terrain", "controller/events/detector"])
        for trial, case in ((t["trial"], t["condition"]) for t in trials):
            touched = events["body/events/terrain"].get(int(trial))
            if case not in NEW_SLOPE or touched is None:
                continue
            t0, new = touched.times[0], NEW_SLOPE[case]
            fired = {}
            if int(trial) in events["controller/events/detector"]:
                e = events["controller/events/detector"][int(trial)]
                for when, text in zip(e.times, e.texts, strict=True):
                    fired.setdefault(detector_of(text), when - t0)
            on_new = np.inf
            for name in feet:
                s = series[name][int(trial)]
                close = (s.times >= t0) & (np.abs(s.values - new) < NEAR_DEG)
                if close.any():
                    on_new = min(on_new, s.times[close][0] - t0)
            pitch = series["body/torso/pitch"][int(trial)]
            tilted = (pitch.times >= t0) & (np.abs(pitch.values) > TORSO_DEG)
            rows.append({
                "seed": seed, "case": case, "foot_on_new_slope": on_new,
                "feet": fired.get("foot_slope", np.nan), "torso_band": fired.get("torso", np.nan),
                "torso_past_10deg": pitch.times[tilted][0] - t0 if tilted.any() else np.inf,
            })  # fmt: skip
    return rows


def contact_patterns(heel_l, toe_l, heel_r, toe_r, n: int) -> dict[str, np.ndarray]:
    """Each tick's share of the last ``n`` ticks with: a heel pressing and its toe not (either foot, the larger),
    a toe pressing and its heel not, and one point of contact of the four."""

    def share(x):
        return np.convolve(x.astype(float), np.ones(n) / n)[: len(x)]

    hl, tl, hr, tr = (np.asarray(v) >= PRESSED for v in (heel_l, toe_l, heel_r, toe_r))
    return {
        "heel only": np.maximum(share(hl & ~tl), share(hr & ~tr)),
        "toe only": np.maximum(share(~hl & tl), share(~hr & tr)),
        "one point": share((hl.astype(int) + tl + hr + tr) == 1),
    }


def since_shared(times: np.ndarray, heel_l, toe_l, heel_r, toe_r, share: float) -> np.ndarray:
    """Each tick's time (s) since both feet last carried at least ``share`` of the feet's summed pressure, counted
    from SETTLED s at the earliest (a stretch begun in the start ramp does not carry its ramp time into the band)."""
    left, right = np.asarray(heel_l) + np.asarray(toe_l), np.asarray(heel_r) + np.asarray(toe_r)
    total = left + right
    shared = (np.minimum(left, right) >= share * total) & (total > 0)
    last = np.maximum(np.maximum.accumulate(np.where(shared, times, times[0])), SETTLED)
    return np.maximum(times - last, 0.0)


def fire_table(walks: list[tuple], signals: dict[str, list[np.ndarray]]) -> list[str]:
    """Per signal (one array per walk): its band, the most any flat walk that did not fall shows from SETTLED s on,
    and per case the walks where it exceeds the band after the touch, the median latency, and how many within 0.5 s
    and before the torso passed TORSO_DEG."""
    flat = [i for i, w in enumerate(walks) if w[0] == "flat" and w[5]]  # a band is measured on walks that did not fall
    if not flat:
        return ["no flat walk of these runs stayed up: no band to measure against"]
    lines = [f"| signal | flat band | {' | '.join(NEW_SLOPE)} |", "|---|---|" + "---|" * len(NEW_SLOPE)]
    for name, values in signals.items():
        band = max(float(values[i][walks[i][1] >= SETTLED].max()) for i in flat)
        cells = []
        for case in NEW_SLOPE:
            latency, t10 = [], []
            for (c, times, _, t0, tilt, *_), v in zip(walks, values, strict=True):
                if c == case and t0 is not None:
                    above = (times >= t0) & (v > band)
                    latency.append(times[above][0] - t0 if above.any() else np.inf)
                    t10.append(tilt)
            latency, t10 = np.array(latency), np.array(t10)
            fired = np.isfinite(latency)
            early = int(((latency <= 0.5) & (latency < t10)).sum())
            when = f"{median(latency[fired]):.2f} s" if fired.any() else "-"
            cells.append(f"{fired.sum()}/{len(latency)}, {when}, {early} early")
        lines.append(f"| {name} | {band:.2f} | " + " | ".join(cells) + " |")
    return lines


class Walk(NamedTuple):
    """A walk of ``detectors{tag}_s0..2``: its case, times, the four feet signals, the touch time (None on the flat),
    the time from the touch until the torso passed TORSO_DEG, whether it stayed up, each sole's pitch in the world
    (deg, left and right), the sensed state (ticks x STATE) and its seed."""

    case: str
    times: np.ndarray
    feet: tuple
    t0: float | None
    t10: float
    up: bool
    soles: tuple
    state: np.ndarray
    seed: int


def feet_walks(runs: Path, tag: str) -> list[Walk]:
    walks = []
    for seed in range(3):
        run = runs / f"detectors{tag}_s{seed}"
        rrd = run / "recording.rrd"
        series = read_series(rrd, STATE)
        touched = read_events(rrd, ["body/events/terrain"])["body/events/terrain"]
        for t in table(run / "trials.parquet"):
            trial = int(t["trial"])
            if trial not in series[FEET[0]]:
                continue
            times = series[FEET[0]][trial].times
            state = np.stack([np.asarray(series[name][trial].values, dtype=float) for name in STATE], axis=1)
            column = {name: state[:, i] for i, name in enumerate(STATE)}
            pitch = column["body/torso/pitch"]
            t0 = touched[trial].times[0] if trial in touched else None
            tilted = (times >= (t0 or 0.0)) & (np.abs(pitch) > TORSO_DEG)
            t10 = times[tilted][0] - t0 if t0 is not None and tilted.any() else np.inf
            feet = tuple(column[f] for f in FEET)
            soles = tuple(pitch + sum(column[f"body/joints/{joint}_{side}"] for joint in CHAIN) for side in "lr")
            walks.append(Walk(t["condition"], times, feet, t0, t10, not t["m_fell"], soles, state, seed))
    return walks


def contact_rows(walks: list[tuple]) -> list[str]:
    patterns = []
    for _, times, feet, *_ in walks:
        n = max(1, int(round(CONTACT_WINDOW / float(np.median(np.diff(times))))))
        patterns.append(contact_patterns(*feet, n))
    return fire_table(walks, {name: [p[name] for p in patterns] for name in ("heel only", "toe only", "one point")})


def shared_rows(walks: list[tuple]) -> list[str]:
    signals = {f"unshared, x {x:g}": [since_shared(times, *feet, x) for _, times, feet, *_ in walks] for x in SHARES}
    return fire_table(walks, signals)


def pitched_past(case: str, feet: tuple, soles: tuple) -> dict[str, np.ndarray]:
    """Each tick's most any foot on its heel alone pitches toe-down past the old ground (deg; 0 when none is on its
    heel alone), and any foot on its toe alone toe-up past it."""
    heel_l, toe_l, heel_r, toe_r = (np.asarray(v) >= PRESSED for v in feet)
    old = OLD_SLOPE[case]
    down, up = np.zeros(len(soles[0])), np.zeros(len(soles[0]))
    for heel, toe, sole in ((heel_l, toe_l, soles[0]), (heel_r, toe_r, soles[1])):
        down = np.maximum(down, np.where(heel & ~toe, old + sole, 0.0))  # the slope under it: -sole (+ = uphill)
        up = np.maximum(up, np.where(toe & ~heel, -sole - old, 0.0))
    return {"heel alone, toe-down past the old ground": down, "toe alone, toe-up past the old ground": up}


def pitched_rows(walks: list[tuple]) -> list[str]:
    signals = [pitched_past(w.case, w.feet, w.soles) for w in walks]
    return fire_table(walks, {name: [p[name] for p in signals] for name in signals[0]})


def gait_phase(hip: np.ndarray, dt: float) -> np.ndarray:
    """Each sample's phase bin (0..PHASES-1) of the hip's oscillation: the angle of (x, -x'/omega) of its deviation
    x from a 0.67-s running mean (omega: the gait's 1.5 Hz)."""
    x = hip - np.convolve(hip, np.ones(17) / 17, mode="same")
    v = np.gradient(x, dt) / (2 * np.pi * GAIT_HZ)
    return ((np.arctan2(-v, x) + np.pi) / (2 * np.pi) * PHASES).astype(int) % PHASES


def novelty_rows(walks: list[Walk]) -> list[str]:
    walks = [w for w in walks if w.case in ("flat", "flatdown", "up")]
    states = []
    for w in walks:
        x = w.state.copy()
        feet = slice(len(JOINTS), len(JOINTS) + len(FEET))
        x[:, feet] = np.minimum(x[:, feet], NOVELTY_PRESS) / 10.0
        states.append((x, gait_phase(x[:, STATE.index("body/joints/hip_pitch_l")], float(np.median(np.diff(w.times))))))
    models = {}  # per seed left out, per phase: the flat walks' mean and inverse covariance
    for seed in {w.seed for w in walks}:
        flat = [(w, st) for w, st in zip(walks, states, strict=True) if w.case == "flat" and w.up and w.seed != seed]
        for b in range(PHASES):
            rows = np.concatenate([x[(phase == b) & (w.times >= SETTLED)] for w, (x, phase) in flat])
            cov = np.cov(rows.T)
            cov += 1e-3 * np.trace(cov) / len(cov) * np.eye(len(cov))  # a little ridge: some signals hardly move
            models[seed, b] = rows.mean(axis=0), np.linalg.inv(cov)
    signals = []
    for w, (x, phase) in zip(walks, states, strict=True):
        distance = np.zeros(len(w.times))
        for b in range(PHASES):
            mean, inverse = models[w.seed, b]
            d = x[phase == b] - mean
            distance[phase == b] = np.sqrt(np.einsum("ij,jk,ik->i", d, inverse, d))
        distance[w.times < SETTLED] = 0.0
        signals.append(np.convolve(distance, np.ones(3) / 3)[: len(w.times)])
    return fire_table(walks, {"novelty against the flat walks (other seeds)": signals})


def _turn(axis: int, angle: np.ndarray) -> np.ndarray:
    """(ticks, 3, 3): rotations by ``angle`` (rad) about x (0) or y (1)."""
    c, s, o, z = np.cos(angle), np.sin(angle), np.ones_like(angle), np.zeros_like(angle)
    rows = ([o, z, z], [z, c, -s], [z, s, c]) if axis == 0 else ([c, z, s], [z, o, z], [-s, z, c])
    return np.stack([np.stack(row, axis=-1) for row in rows], axis=-2)


def pressed_points(w: Walk) -> list[np.ndarray]:
    """Per foot (left, right), each tick's pressed point relative to the torso's origin in a frame level with the
    ground's normal and the torso's heading (m; heel, toe or their middle; NaN when the foot presses neither)."""
    column = {name: np.radians(w.state[:, i]) for i, name in enumerate(STATE)}
    points = []
    for side, (heel, toe) in zip("lr", (w.feet[:2], w.feet[2:]), strict=True):
        q = {joint: column[f"body/joints/{joint}_{side}"] for joint in LEG}
        turn = _turn(1, column["body/torso/pitch"]) @ _turn(0, column["body/torso/roll"])
        at = turn @ np.array([HIP[0], HIP[1] if side == "l" else -HIP[1], HIP[2]])
        turn = turn @ _turn(0, q["hip_roll"]) @ _turn(1, q["hip_pitch"])
        at = at + turn @ np.array([0.0, 0.0, -THIGH])
        turn = turn @ _turn(1, q["knee"])
        at = at + turn @ np.array([0.0, 0.0, -TIBIA])
        turn = turn @ _turn(1, q["ankle_pitch"]) @ _turn(0, q["ankle_roll"])
        toe_at, heel_at = (at + turn @ np.array([x, 0.0, -SOLE]) for x in FSR_X)
        on_heel, on_toe = (np.asarray(heel) >= PRESSED)[:, None], (np.asarray(toe) >= PRESSED)[:, None]
        count = on_heel.astype(float) + on_toe
        point = (heel_at * on_heel + toe_at * on_toe) / np.where(count == 0, 1.0, count)
        point[count[:, 0] == 0] = np.nan
        points.append(point)
    return points


def feet_line_rows(walks: list[Walk]) -> list[str]:
    lines, signals, apart = [], {f"feet >= {d * 100:g} cm apart": [] for d in SPACING}, []
    for w in walks:
        left, right = pressed_points(w)
        ahead = left - right  # the left foot's point from the right's
        fore = np.abs(ahead[:, 0])
        slope = np.degrees(np.arctan2(np.sign(ahead[:, 0]) * ahead[:, 2], fore))  # + = the front foot higher
        both = np.isfinite(slope)
        if w.case == "flat" and w.up:
            apart.append(fore[both & (w.times >= SETTLED)])
        for spacing, values in zip(SPACING, signals.values(), strict=True):
            values.append(np.where(both & (fore >= spacing), np.abs(slope - OLD_SLOPE[w.case]), 0.0))
    lines.append("the feet's fore-and-aft distance in double support on the flat walks that stayed up, from 5 s on: "
                 "quartiles " + ", ".join(f"{q * 100:.1f}" for q in np.percentile(np.concatenate(apart), [25, 50, 75]))
                 + " cm")  # fmt: skip
    return lines + fire_table(walks, signals)


def downhill_without(runs: Path, tag: str) -> list[str]:
    sweep = table(runs / "presweep" / "trials.parquet")
    axes = ["gain_pitch", "gain_roll", "sigma_s"]
    cells = np.array([[row[a] for a in axes] for row in sweep])
    walked = np.array([bool(row["success"]) for row in sweep])
    low, high = cells.min(axis=0), cells.max(axis=0)
    lines = []
    for seed in range(3):
        walks = [t for t in table(runs / f"switch{tag}_s{seed}" / "trials.parquet") if t["condition"] == "down_without"]
        neuron = np.array([walks[0][f"controller.{a}"] for a in axes])
        nearest = np.argsort(np.linalg.norm((cells - neuron) / (high - low), axis=1))[:8]
        on = sum(bool(t["success"]) for t in walks)
        lines.append(f"seed {seed}: neuron {np.round(neuron, 2).tolist()} walks on {on}/{len(walks)}; "
                     f"its 8 nearest pre-sweep cells walk the flat {int(walked[nearest].sum())}/8")  # fmt: skip
    return lines


def main(argv: list[str]) -> int:
    if len(argv) != 1 or not Path(argv[0]).is_dir():
        print("usage: python docs/experiments/e5_why.py RUNS (chapter5.sh's run folder)", file=sys.stderr)
        return 2
    runs = Path(argv[0])
    for tag, name in (("", "the thesis's neuron"), ("_wins", "the most-winning neuron")):
        print(f"## {name} (detectors{tag}_s0..2, switch{tag}_s0..2)\n")
        times = edge_times(runs, tag)
        keys = ["foot_on_new_slope", "feet", "torso_band", "torso_past_10deg"]
        print("s after a foot first touched the next piece, medians over the walks (a detector that never fired, or")
        print("fired before the touch, left out; inf: never within the walk)")
        print("| case | " + " | ".join(keys) + " |")
        for case in NEW_SLOPE:
            mine = [r for r in times if r["case"] == case]
            cells = [median([r[k] for r in mine if np.isfinite(r[k]) and r[k] > 0] or [np.inf]) for k in keys]
            print(f"| {case} | " + " | ".join(f"{c:.2f}" for c in cells) + " |")
        for case in ("flatdown", "upflat"):
            mine = [r for r in times if r["case"] == case]
            fired = [r for r in mine if np.isfinite(r["feet"]) and r["feet"] > 0]
            print(
                f"{case}: {len(mine)} walks; the feet fired after the touch in {len(fired)}, before a foot sensed "
                f"the new slope in {sum(r['feet'] < r['foot_on_new_slope'] for r in fired)}, before the torso passed "
                f"{TORSO_DEG:g} deg in {sum(r['feet'] < r['torso_past_10deg'] for r in fired)} (median "
                f"{median([r['torso_past_10deg'] - r['feet'] for r in fired]):.2f} s before)"
            )
        print(f"\nthe feet's contacts, each pattern's share of the last {CONTACT_WINDOW:g} s (fires: walks where it")
        print("exceeds the flat walks' band after the touch, the median latency, and how many within 0.5 s and before")
        print(f"the torso passed {TORSO_DEG:g} deg):")
        walks = feet_walks(runs, tag)
        print("\n".join(contact_rows(walks)))
        for heading, rows in (
            ("the weight shared between the feet: s since both feet last carried at least a share x of the feet's\n"
             "summed pressure (fires, latency and early as above):", shared_rows),
            ("a foot on its heel (toe) alone pitched toe-down (toe-up) past the slope of the ground walked before\n"
             "the edge, deg (fires, latency and early as above):", pitched_rows),
            ("the sensed state's distance from the flat walks' at the same gait phase (walks that start on the\n"
             "flat; up -> flat and down -> flat start on a ramp and are left out):", novelty_rows),
            ("the slope of the line between the feet's pressed points against the ground walked before the edge,\n"
             "deg (fires, latency and early as above):", feet_line_rows),
        ):  # fmt: skip
            print("\n" + heading)
            print("\n".join(rows(walks)))
        print("\ndownhill -> flat without switching:")
        print("\n".join(downhill_without(runs, tag)), "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
